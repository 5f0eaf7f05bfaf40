"""Transport of the controller link: bytes in and out of a serial port (pyserial-asyncio).

:class:`SerialLink` is the lowest layer.  It knows nothing of frames: received bytes go to a
sink callback, and the end of the connection flows one way, upwards: pyserial-asyncio calls
``connection_lost(exc)``, the link resolves :attr:`SerialLink.closed` with the reason, and the
layers above (the device API, the driver's supervisor) react; nothing above calls back down
into a dead link.  A new connection is a new :class:`SerialLink`.

The link also offers the urgent write path used by the emergency stop
(:meth:`SerialLink.write_urgent`): it throws away every byte not yet on the wire (the
transport's buffer and the kernel's output queue) and writes an LF, which ends any frame cut
in half by the flush so the controller discards it, before the urgent frame.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable

import serial
import serial_asyncio

from robot.errors import LinkDown

__all__ = ["SerialLink"]


class _LinkTransport(serial_asyncio.SerialTransport):
    """pyserial-asyncio's transport, with a failed write ending the connection as quietly
    as a failed read does.

    When the port vanishes (a USB adapter pulled, the pseudo-terminal's other end gone) the
    first ``read`` or ``write`` fails with EIO.  pyserial-asyncio closes the connection on a
    failed read, but reports a failed write to the event loop's exception handler ("Fatal
    write error on serial transport", logged as an unhandled error) before closing: which of
    the two sees the fault first is a race, so a routine outage sometimes looked like a bug
    in the logs.  asyncio's own socket and pipe transports treat an ``OSError`` so (the
    handler is reserved for the unexpected; ``SerialException`` is an ``OSError``): the
    connection ends through ``connection_lost(exc)`` either way, and :class:`SerialLink`
    reports it upwards with the reason.
    """

    def _fatal_error(self, exc: BaseException, message: str = "Fatal error on serial transport") -> None:  # fmt: skip
        if isinstance(exc, OSError):
            self._abort(exc)
        else:
            super()._fatal_error(exc, message)


class SerialLink(asyncio.Protocol):
    """One open serial connection.

    Use :meth:`open`; do not construct directly.

    Attributes
    ----------
    port : str
        Device path that was opened (a symlink is fine and is re-resolved at every open).
    closed : asyncio.Future
        Resolves with the exception that ended the connection (``None`` after :meth:`close`).
    bytes_in, bytes_out : int
        Byte counters for this connection.
    """

    def __init__(self, port: str, on_bytes: Callable[[bytes], None]) -> None:
        self.port = port
        self._on_bytes = on_bytes
        self._transport: serial_asyncio.SerialTransport | None = None
        self.closed: asyncio.Future[BaseException | None] = (
            asyncio.get_running_loop().create_future()
        )
        self.bytes_in = 0
        self.bytes_out = 0

    @classmethod
    async def open(cls, port: str, *, baud: int, on_bytes: Callable[[bytes], None]) -> SerialLink:
        """Open ``port`` at ``baud`` baud, 8 data bits, no parity, 1 stop bit, no flow control.

        Parameters
        ----------
        port : str
            Device path, e.g. ``/dev/ttyUSB0`` or a symlink to a pseudo-terminal.
        baud : int
            Line speed in bit/s (a pseudo-terminal accepts and ignores it).
        on_bytes : callable
            Called on the event loop with every chunk of received bytes.

        Raises
        ------
        LinkDown
            If the port cannot be opened (missing, busy, not a serial device).
        """
        loop = asyncio.get_running_loop()
        link = cls(port, on_bytes)
        try:
            ser = serial.serial_for_url(
                port,
                baudrate=baud,
                bytesize=serial.EIGHTBITS,
                parity=serial.PARITY_NONE,
                stopbits=serial.STOPBITS_ONE,
                xonxoff=False,
                rtscts=False,
                exclusive=True,
            )
        except (serial.SerialException, OSError, ValueError) as exc:
            raise LinkDown(f"cannot open serial port {port!r}: {exc}") from exc
        try:
            _LinkTransport(loop, link, ser)  # calls connection_made on the next iteration
        except BaseException:
            ser.close()
            raise
        # connection_made runs on the next loop iteration; wait for it.
        while link._transport is None and not link.closed.done():
            await asyncio.sleep(0)
        if link.closed.done():
            raise LinkDown(f"serial port {port!r} closed while opening: {link.closed.result()}")
        return link

    # -- asyncio.Protocol ---------------------------------------------------------------------
    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, serial_asyncio.SerialTransport)
        self._transport = transport

    def data_received(self, data: bytes) -> None:
        self.bytes_in += len(data)
        self._on_bytes(data)

    def connection_lost(self, exc: Exception | None) -> None:
        self._transport = None
        if not self.closed.done():
            self.closed.set_result(exc)

    # -- writing ------------------------------------------------------------------------------
    @property
    def is_open(self) -> bool:
        """True until the connection is lost or closed."""
        return self._transport is not None and not self._transport.is_closing()

    def write(self, data: bytes) -> None:
        """Queue ``data`` for sending, behind anything already queued.

        Raises
        ------
        LinkDown
            If the connection is gone.
        """
        if not self.is_open:
            raise LinkDown(f"serial link {self.port!r} is closed")
        assert self._transport is not None
        self._transport.write(data)
        self.bytes_out += len(data)

    def write_urgent(self, data: bytes) -> None:
        """Send ``data`` ahead of everything queued: drop unsent bytes, then LF + ``data``."""
        if not self.is_open:
            raise LinkDown(f"serial link {self.port!r} is closed")
        assert self._transport is not None
        self._transport.flush()  # pyserial-asyncio's own buffer
        with contextlib.suppress(serial.SerialException, OSError):
            self._transport.serial.reset_output_buffer()  # the kernel's output queue
        self._transport.write(b"\n" + data)
        self.bytes_out += len(data) + 1

    @property
    def write_buffer_size(self) -> int:
        """Bytes handed to the transport and not yet written to the device."""
        return 0 if self._transport is None else self._transport.get_write_buffer_size()

    def close(self) -> None:
        """Close the port (idempotent); :attr:`closed` then resolves with ``None``."""
        if self._transport is not None:
            self._transport.close()
