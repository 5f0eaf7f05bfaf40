"""The link supervisor: keeps one controller link open, reconnecting with backoff.

:class:`LinkSupervisor` owns the life of the :class:`~robot.drivers.serial.transport.SerialLink`
under a :class:`~robot.drivers.serial.device.SerialDevice`:

1. open the port (a missing or busy port is an ordinary failure, not an exception upwards);
2. attach it to the device and run the driver's handshake (``HELLO`` and the rest);
3. mark the link ready, then watch it: the transport's ``connection_lost`` ends it, and so
   does silence (nothing received for ``silence_timeout_s``; a real RS-232 cable pulled out
   of a USB adaptor leaves the port open but dead).  While it is up, a heartbeat ``PING``
   goes out whenever nothing was sent for ``heartbeat_s``, so the controller's watchdog
   knows the host is alive;
4. when the link ends: detach, tell the driver (``on_down``), and go back to 1.

Failed attempts wait ``backoff_initial_s`` doubling up to ``backoff_max_s``, each wait
multiplied by a random factor in [0.5, 1] (jitter, so that the cells of a plant do not retry in
step); a success resets the delay.  The first retry after losing a working link is
immediate.  The cap bounds how long a returned port goes unnoticed.  One warning is logged
when an outage starts and one info line when it ends, however many attempts it took.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import random
import time
from collections.abc import Awaitable, Callable

from robot.drivers.serial.device import SerialDevice
from robot.drivers.serial.frames import Ping
from robot.drivers.serial.transport import SerialLink
from robot.errors import LinkDown, RobotError

__all__ = ["LinkSupervisor"]

log = logging.getLogger("robot.drivers.serial.driver")


class LinkSupervisor:
    """Open, hand-shake, watch and re-open one serial link.

    Parameters
    ----------
    port : str
        Device path (re-resolved at every attempt, so a symlink that moves is followed).
    baud : int
        Line speed, bit/s.
    device : SerialDevice
        The command layer to attach each new link to.
    handshake : callable
        Coroutine run on every new link before it counts as ready; raising fails the
        attempt.
    on_down : callable
        Called with a short reason whenever the link is not usable (each failed attempt and
        each loss), on the event loop.
    heartbeat_s, silence_timeout_s : float
        Idle time before a ``PING``; silence after which the link is declared dead.
    command_timeout_s : float
        Timeout of the heartbeat ``PING``.
    backoff_initial_s, backoff_max_s : float
        First retry delay and its cap.
    rng : random.Random
        Source of the jitter.
    """

    def __init__(
        self,
        port: str,
        *,
        baud: int,
        device: SerialDevice,
        handshake: Callable[[], Awaitable[None]],
        on_down: Callable[[str], None],
        heartbeat_s: float,
        silence_timeout_s: float,
        command_timeout_s: float,
        backoff_initial_s: float,
        backoff_max_s: float,
        rng: random.Random,
    ) -> None:
        self.port = port
        self.baud = baud
        self.device = device
        self._handshake = handshake
        self._on_down = on_down
        self.heartbeat_s = heartbeat_s
        self.silence_timeout_s = silence_timeout_s
        self.command_timeout_s = command_timeout_s
        self.backoff_initial_s = backoff_initial_s
        self.backoff_max_s = backoff_max_s
        self._rng = rng
        self.ready = asyncio.Event()
        """Set while a link is open and its handshake succeeded."""
        self.closed = False
        """True after :meth:`stop`."""
        self.outages = 0
        """Outages seen (each logged once)."""
        self.last_outage_s = 0.0
        """Length of the last outage that ended, seconds."""
        self.connected_at = 0.0
        """``time.monotonic()`` when the link was last (re-)established."""
        self.link: SerialLink | None = None
        self._outage_since: float | None = None
        self._close_reason: str | None = None
        self._tasks: list[asyncio.Task[None]] = []
        self._ping: asyncio.Task[None] | None = None

    def start(self) -> None:
        """Start supervising (idempotent)."""
        self.closed = False
        if not self._tasks:
            self._tasks = [
                asyncio.create_task(self._run(), name="serial-supervisor"),
                asyncio.create_task(self._heartbeat(), name="serial-heartbeat"),
            ]

    async def stop(self) -> None:
        """Stop supervising and close the link (idempotent)."""
        self.closed = True
        tasks = [*self._tasks, *([self._ping] if self._ping else [])]
        for t in tasks:
            t.cancel()
        for t in tasks:
            with contextlib.suppress(asyncio.CancelledError):
                await t
        self._tasks, self._ping = [], None
        if self.link is not None:
            self.link.close()
            self.link = None
        self.ready.clear()

    async def wait_ready(self, timeout_s: float) -> bool:
        """Wait up to ``timeout_s`` for the link to be ready; False on timeout or after stop."""
        if self.closed:
            return False
        try:
            async with asyncio.timeout(timeout_s):
                await self.ready.wait()
        except TimeoutError:
            return False
        return not self.closed

    # -- internals ----------------------------------------------------------------------------
    def _backoff(self, delay: float) -> tuple[float, float]:
        """(jittered wait now, next delay)."""
        return delay * self._rng.uniform(0.5, 1.0), min(2.0 * delay, self.backoff_max_s)

    async def _run(self) -> None:
        delay = self.backoff_initial_s
        while True:
            try:
                link = await SerialLink.open(self.port, baud=self.baud, on_bytes=self.device.feed)
            except LinkDown as exc:
                self._note_down(str(exc))
                wait, delay = self._backoff(delay)
                await asyncio.sleep(wait)
                continue
            self.link = link
            self.device.attach(link)
            handshake = asyncio.create_task(self._handshake())
            ok = False
            try:
                await asyncio.wait({handshake, link.closed}, return_when=asyncio.FIRST_COMPLETED)
                ok = (
                    handshake.done() and not handshake.cancelled() and handshake.exception() is None
                )
                if ok:
                    self.ready.set()
                    self.connected_at = time.monotonic()
                    delay = self.backoff_initial_s
                    self._note_up()
                    await link.closed
                    why = self._close_reason or f"serial link lost ({link.closed.result()})"
                else:
                    handshake.cancel()
                    with contextlib.suppress(asyncio.CancelledError, Exception):
                        await handshake
                    exc = None if handshake.cancelled() else handshake.exception()
                    why = f"handshake failed: {exc or 'port closed'}"
            finally:
                self.ready.clear()
                self.device.detach()
                link.close()
                self.link = None
            self._close_reason = None
            self._note_down(why)
            if not ok:
                wait, delay = self._backoff(delay)
                await asyncio.sleep(wait)

    async def _heartbeat(self) -> None:
        while True:
            await asyncio.sleep(self.heartbeat_s / 2)
            link = self.link
            if not self.ready.is_set() or link is None:
                continue
            now = time.monotonic()
            if now - self.device.last_rx_s > self.silence_timeout_s:
                self._close_reason = f"controller silent for {self.silence_timeout_s:g} s"
                link.close()
            elif now - self.device.last_tx_s >= self.heartbeat_s and (
                self._ping is None or self._ping.done()
            ):
                self._ping = asyncio.create_task(self._quiet_ping())

    async def _quiet_ping(self) -> None:
        with contextlib.suppress(RobotError):
            await self.device.request(lambda s: Ping(s), timeout_s=self.command_timeout_s)

    def _note_down(self, why: str) -> None:
        if self._outage_since is None:
            self._outage_since = time.monotonic()
            self.outages += 1
            log.warning("serial controller at %s unreachable (%s); reconnecting", self.port, why)
        self._on_down(why)

    def _note_up(self) -> None:
        if self._outage_since is not None:
            self.last_outage_s = time.monotonic() - self._outage_since
            log.info(
                "serial controller at %s reachable again after %.2f s",
                self.port,
                self.last_outage_s,
            )
            self._outage_since = None
