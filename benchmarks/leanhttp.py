"""A lean HTTP/1.1 GET client on asyncio streams, for load generators.

The load benchmark's clients stand in for consoles on other machines; their own CPU
competes with the server on the benchmark's machine only.  httpx spends about a
millisecond of Python per request (its pool, its models, its header handling); this
client reads one keep-alive connection with a fixed request head and parses only the
status line, ``content-length`` or chunked framing, and ``connection: close``.

It speaks just what the benchmark needs: ``GET``, keep-alive, identity or chunked
bodies, answers up to :data:`MAX_BODY_BYTES`.  Anything else raises :class:`HttpError`.
"""

from __future__ import annotations

import asyncio
import contextlib
from urllib.parse import urlsplit

__all__ = ["MAX_BODY_BYTES", "HttpError", "LeanConnection"]

#: Largest answer body read, bytes (a camera frame is well below).
MAX_BODY_BYTES = 32 << 20
#: Largest answer head (status line and headers), bytes.
MAX_HEAD_BYTES = 64 << 10


class HttpError(Exception):
    """No usable answer: connection refused or lost, malformed answer, or a timeout."""


class LeanConnection:
    """One keep-alive HTTP/1.1 connection to ``base`` (``http://host:port``) sending
    ``GET`` requests with ``headers``; it reconnects after the server closes it.

    Parameters
    ----------
    base : str
        ``http://host:port`` (no path, no TLS).
    headers : dict of str to str
        Sent with every request (e.g. ``Authorization``); names and values in ASCII.
    timeout_s : float
        Per request (connect, send, read the whole answer), seconds, in (0, 600].
    """

    def __init__(self, base: str, *, headers: dict[str, str], timeout_s: float) -> None:
        parts = urlsplit(base)
        if parts.scheme != "http" or not parts.hostname or parts.path not in ("", "/"):
            raise ValueError(f"base must be http://host[:port], got {base!r}")
        if not (isinstance(timeout_s, int | float) and 0 < timeout_s <= 600):
            raise ValueError(f"timeout_s must be within (0, 600] s, got {timeout_s!r}")
        for k, v in headers.items():
            if not (k.isascii() and v.isascii()) or any(c in k + v for c in "\r\n"):
                raise ValueError(f"header {k!r} must be ASCII without line breaks")
        self.host = parts.hostname
        self.port = parts.port or 80
        self.timeout_s = float(timeout_s)
        hostport = f"{self.host}:{self.port}"
        extra = "".join(f"{k}: {v}\r\n" for k, v in headers.items())
        self._head_tail = f" HTTP/1.1\r\nHost: {hostport}\r\n{extra}\r\n".encode("ascii")
        self._reader: asyncio.StreamReader | None = None
        self._writer: asyncio.StreamWriter | None = None

    async def get(self, target: str) -> tuple[int, bytes]:
        """``GET target`` (a path with its query); the status code and the body."""
        if not target.startswith("/") or not target.isascii() or " " in target:
            raise ValueError(f"target must be an ASCII path starting with '/', got {target!r}")
        try:
            async with asyncio.timeout(self.timeout_s):
                return await self._get(target)
        except (OSError, TimeoutError, asyncio.IncompleteReadError, asyncio.LimitOverrunError,
                ValueError) as exc:  # fmt: skip
            await self.close()
            raise HttpError(f"GET {target}: {type(exc).__name__}: {exc}") from exc

    async def _get(self, target: str) -> tuple[int, bytes]:
        if self._writer is None or self._writer.is_closing():
            self._reader, self._writer = await asyncio.open_connection(
                self.host, self.port, limit=MAX_HEAD_BYTES
            )
        reader, writer = self._reader, self._writer
        assert reader is not None
        writer.write(b"GET " + target.encode("ascii") + self._head_tail)
        head = await reader.readuntil(b"\r\n\r\n")
        lines = head.split(b"\r\n")
        status_line = lines[0].split(b" ", 2)
        if len(status_line) < 2 or not status_line[0].startswith(b"HTTP/1."):
            raise ValueError(f"not an HTTP/1.x status line: {lines[0][:80]!r}")
        status = int(status_line[1])
        length: int | None = None
        chunked = close = False
        for line in lines[1:]:
            name, _, value = line.partition(b":")
            name = name.strip().lower()
            if name == b"content-length":
                length = int(value)
            elif name == b"transfer-encoding":
                chunked = b"chunked" in value.lower()
            elif name == b"connection":
                close = value.strip().lower() == b"close"
        if chunked:
            body = await self._read_chunked(reader)
        elif length is not None:
            if not 0 <= length <= MAX_BODY_BYTES:
                raise ValueError(f"content-length {length} out of 0..{MAX_BODY_BYTES}")
            body = await reader.readexactly(length)
        elif status in (204, 304) or 100 <= status < 200:
            body = b""
        else:  # no framing: the body ends with the connection
            body = await reader.read(MAX_BODY_BYTES)
            close = True
        if close:
            await self.close()
        return status, body

    @staticmethod
    async def _read_chunked(reader: asyncio.StreamReader) -> bytes:
        parts: list[bytes] = []
        total = 0
        while True:
            size_line = await reader.readuntil(b"\r\n")
            size = int(size_line.split(b";", 1)[0].strip(), 16)
            if size == 0:
                while (await reader.readuntil(b"\r\n")) != b"\r\n":  # trailers
                    pass
                return b"".join(parts)
            total += size
            if total > MAX_BODY_BYTES:
                raise ValueError(f"chunked body over {MAX_BODY_BYTES} bytes")
            parts.append(await reader.readexactly(size))
            if await reader.readexactly(2) != b"\r\n":
                raise ValueError("a chunk does not end with CRLF")

    async def close(self) -> None:
        """Close the connection (the next request opens a new one)."""
        writer, self._writer, self._reader = self._writer, None, None
        if writer is not None:
            writer.close()
            with contextlib.suppress(OSError):
                await writer.wait_closed()
