"""The device end of a pseudo-terminal, published at a stable path.

A controller emulator cannot own a real serial port, so it opens a pseudo-terminal pair with
:func:`os.openpty`: the emulator reads and writes the master side, and the host opens the
slave side (``/dev/pts/N``) exactly as it would open ``/dev/ttyUSB0``, through pyserial.  The
master is put in raw mode at once (:func:`tty.setraw`), otherwise the line discipline would
echo the emulator's own output back to it before the host has configured the port.

Because ``/dev/pts/N`` changes whenever the pair is re-created, the port is published as a
symbolic link (``link``, e.g. ``var/robot-tty``) that always points at the current slave.
:meth:`PtyPort.vanish` closes both ends and removes the link, which is what the host sees
when a USB adaptor is unplugged: reads fail at once and the path disappears;
:meth:`PtyPort.reopen` creates a new pair and points the link at it, so a driver that
retries the same path reconnects.

The emulator keeps its own descriptor of the slave open, so the master never reads EIO while
no host is attached.  Output that the host is not reading piles up in the kernel buffer and
then in a bounded user-space buffer; beyond that it is dropped, as a UART with nobody
listening would lose it.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import tempfile
import tty
from collections.abc import Callable
from pathlib import Path

__all__ = ["PtyPort"]

_TX_BUFFER_LIMIT = 64 * 1024


class PtyPort:
    """One pseudo-terminal pair whose slave is reachable at :attr:`path`.

    Parameters
    ----------
    on_bytes : callable
        Called on the event loop with every chunk of bytes the host wrote.
    link : str or path, optional
        Where to publish the slave.  Default: ``robot-tty`` in a new temporary directory,
        removed by :meth:`close`.  An existing symlink at ``link`` is replaced; any other
        existing file there is an error.
    """

    def __init__(
        self, on_bytes: Callable[[bytes], None], *, link: str | os.PathLike[str] | None
    ) -> None:
        self._on_bytes = on_bytes
        self._tmpdir: str | None = None
        if link is None:
            self._tmpdir = tempfile.mkdtemp(prefix="visioncell-tty-")
            link = Path(self._tmpdir) / "robot-tty"
        self.path = str(Path(link).absolute())
        if os.path.lexists(self.path) and not os.path.islink(self.path):
            raise ValueError(f"link must be a free path or an old symlink, got {self.path!r}")
        self._master: int | None = None
        self._slave: int | None = None
        self._tx = bytearray()
        self._writing = False
        self.device = ""
        self.tx_dropped = 0

    @property
    def is_open(self) -> bool:
        """True while the pair exists (between :meth:`reopen` and :meth:`vanish`)."""
        return self._master is not None

    def reopen(self) -> str:
        """Create a fresh pair, point :attr:`path` at its slave, start reading; returns the path."""
        if self._master is not None:
            return self.path
        master, slave = os.openpty()
        tty.setraw(master)
        os.set_blocking(master, False)
        self._master, self._slave = master, slave
        self.device = os.ttyname(slave)
        Path(self.path).parent.mkdir(parents=True, exist_ok=True)
        tmp = f"{self.path}.{os.getpid()}.tmp"
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        os.symlink(self.device, tmp)
        os.replace(tmp, self.path)  # atomic: the path never points nowhere while re-linking
        asyncio.get_running_loop().add_reader(master, self._readable)
        return self.path

    def vanish(self) -> None:
        """Close both ends and remove the link: the host's reads fail, the path is gone."""
        if self._master is None:
            return
        loop = asyncio.get_running_loop()
        loop.remove_reader(self._master)
        if self._writing:
            loop.remove_writer(self._master)
            self._writing = False
        self._tx.clear()
        with contextlib.suppress(FileNotFoundError):
            if os.path.islink(self.path) and os.readlink(self.path) == self.device:
                os.unlink(self.path)
        for fd in (self._master, self._slave):
            with contextlib.suppress(OSError):
                os.close(fd)  # type: ignore[arg-type]
        self._master = self._slave = None

    def close(self) -> None:
        """Vanish for good and remove the temporary directory if this port made one."""
        self.vanish()
        if self._tmpdir is not None:
            with contextlib.suppress(OSError):
                os.rmdir(self._tmpdir)
            self._tmpdir = None

    def write(self, data: bytes) -> None:
        """Send ``data`` to the host without blocking (dropped while vanished or overfull)."""
        if self._master is None:
            self.tx_dropped += len(data)
            return
        if len(self._tx) + len(data) > _TX_BUFFER_LIMIT:
            self.tx_dropped += len(data)
            return
        self._tx += data
        self._flush()

    def _flush(self) -> None:
        assert self._master is not None
        while self._tx:
            try:
                n = os.write(self._master, self._tx)
            except BlockingIOError:
                break
            except OSError:
                self.tx_dropped += len(self._tx)
                self._tx.clear()
                break
            del self._tx[:n]
        loop = asyncio.get_running_loop()
        if self._tx and not self._writing:
            loop.add_writer(self._master, self._flush)
            self._writing = True
        elif not self._tx and self._writing:
            loop.remove_writer(self._master)
            self._writing = False

    def _readable(self) -> None:
        assert self._master is not None
        try:
            data = os.read(self._master, 4096)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            return  # EIO while no slave is open; we keep one open, so this is transient
        if data:
            self._on_bytes(data)
