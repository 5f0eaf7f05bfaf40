"""Framing of the controller link: ASCII lines sealed with a CRC-16 checksum.

A frame on the wire is one line ``BODY*CCCC\\n`` (``docs/serial-protocol.md`` section 2):

* ``BODY`` is printable ASCII (0x20-0x7E) without ``*``;
* ``CCCC`` is the CRC-16/CCITT-FALSE of the ``BODY`` bytes as four upper-case hex digits;
* the line ends with LF; one CR just before the LF is tolerated and removed;
* empty lines are ignored (a sender may emit a bare LF to resynchronise the receiver);
* a line longer than :data:`MAX_LINE_BYTES` is discarded up to its LF.

CRC-16/CCITT-FALSE (polynomial 0x1021, initial value 0xFFFF, no reflection, no final XOR;
catalogued as CRC-16/IBM-3740 in Greg Cook's "Catalogue of parametrised CRC algorithms",
check value ``0x29B1`` for ``b"123456789"``) detects every error burst of up to 16 bits, so
every single-byte change, and, because 0x1021 has the factor (x + 1), every odd number of bit
errors; its Hamming distance is 4 for messages up to 32,751 bits (Koopman and Chakravarty,
"Cyclic Redundancy Code (CRC) Polynomial Selection for Embedded Networks", DSN 2004), far
above our 256-byte lines.  Four hex digits keep lines short at 115,200 baud.
"""

from __future__ import annotations

from robot.errors import ProtocolError

__all__ = ["MAX_LINE_BYTES", "LineReader", "crc16_ccitt", "seal", "unseal"]

MAX_LINE_BYTES = 256
"""Longest accepted line in bytes, not counting the terminating LF."""

_CRC_POLY = 0x1021


def _crc_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ _CRC_POLY) if crc & 0x8000 else (crc << 1)
        table.append(crc & 0xFFFF)
    return tuple(table)


_TABLE = _crc_table()
_HEX_DIGITS = frozenset(b"0123456789ABCDEF")


def crc16_ccitt(data: bytes) -> int:
    """CRC-16/CCITT-FALSE of ``data`` (poly 0x1021, init 0xFFFF, MSB first, no final XOR).

    Examples
    --------
    >>> hex(crc16_ccitt(b"123456789"))
    '0x29b1'
    """
    crc = 0xFFFF
    for b in data:
        crc = ((crc << 8) & 0xFFFF) ^ _TABLE[(crc >> 8) ^ b]
    return crc


def _body_ok(body: bytes) -> bool:
    return all(0x20 <= b <= 0x7E and b != 0x2A for b in body)


def seal(body: str) -> bytes:
    """Wire bytes of the frame whose body is ``body``: ``BODY*CCCC\\n``.

    Raises
    ------
    ValueError
        If ``body`` is empty, holds a character outside printable ASCII or a ``*``, or
        makes the line longer than :data:`MAX_LINE_BYTES`.
    """
    if not body or not all(" " <= c <= "~" and c != "*" for c in body):
        raise ValueError(f"body must be non-empty printable ASCII without '*', got {body!r}")
    raw = body.encode("ascii")
    if len(raw) + 5 > MAX_LINE_BYTES:
        raise ValueError(
            f"body makes a {len(raw) + 5}-byte line, longer than {MAX_LINE_BYTES}: {body[:40]!r}..."
        )
    return raw + b"*%04X\n" % crc16_ccitt(raw)


def unseal(line: bytes) -> str:
    """Check one received line (without its LF) and return its body.

    Raises
    ------
    ProtocolError
        If the line lacks the ``*CCCC`` trailer, holds a byte outside printable ASCII, or
        its checksum does not match.
    """
    if line.endswith(b"\r"):
        line = line[:-1]
    if len(line) < 6 or line[-5] != 0x2A:
        raise ProtocolError(f"no '*CCCC' checksum trailer in {line[:40]!r}")
    body, digits = line[:-5], line[-4:]
    if not all(d in _HEX_DIGITS for d in digits):
        raise ProtocolError(f"checksum {digits!r} is not four upper-case hex digits")
    if not _body_ok(body):
        raise ProtocolError(f"frame body holds a byte outside printable ASCII: {body[:40]!r}")
    if int(digits, 16) != crc16_ccitt(body):
        raise ProtocolError(
            f"checksum mismatch: got {digits.decode()}, computed {crc16_ccitt(body):04X}"
        )
    return body.decode("ascii")


class LineReader:
    """Splits a byte stream into LF-terminated lines, discarding over-long ones.

    Parameters
    ----------
    max_line_bytes : int
        Longest line kept, not counting the LF.  Longer lines are dropped whole (up to and
        including their LF) and counted in :attr:`overlong`, so a receiver never buffers more
        than ``max_line_bytes`` bytes of garbage.
    """

    def __init__(self, max_line_bytes: int = MAX_LINE_BYTES) -> None:
        if max_line_bytes < 6:
            raise ValueError(f"max_line_bytes must be at least 6, got {max_line_bytes!r}")
        self.max_line_bytes = int(max_line_bytes)
        self.overlong = 0
        self._buf = bytearray()
        self._discarding = False

    def feed(self, data: bytes) -> list[bytes]:
        """Add received bytes; return the complete lines they finish (LF removed)."""
        self._buf += data
        lines: list[bytes] = []
        while True:
            i = self._buf.find(b"\n")
            if i < 0:
                break
            line = bytes(self._buf[:i])
            del self._buf[: i + 1]
            if self._discarding:
                self._discarding = False
            elif len(line) > self.max_line_bytes:
                self.overlong += 1
            elif line not in (b"", b"\r"):
                lines.append(line)
        if len(self._buf) > self.max_line_bytes:
            # No LF in sight: drop what we hold and skip the rest of this line.
            if not self._discarding:
                self.overlong += 1
            self._discarding = True
            self._buf.clear()
        return lines

    def clear(self) -> None:
        """Forget any partial line (after the link was re-opened)."""
        self._buf.clear()
        self._discarding = False
