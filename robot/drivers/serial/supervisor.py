"""The link supervisor: keeps one controller link open, reconnecting with backoff.

:class:`LinkSupervisor` owns the life of the :class:`~robot.drivers.serial.transport.SerialLink`
under a :class:`~robot.drivers.serial.device.SerialDevice`:

1. open the port (a missing or busy port is an ordinary failure, not an exception upwards);
2. attach it to the device and run the driver's handshake (``HELLO`` and the rest);
3. mark the link ready, then watch it: the transport's ``connection_lost`` ends it, and so
   does silence (nothing received for ``silence_timeout_s`` of the host's own running time:
   a stall of this process is not the controller's silence; a real RS-232 cable pulled out
   of a USB adaptor leaves the port open but dead).  While it is up, a heartbeat ``PING``
   goes out whenever nothing was sent for ``heartbeat_s``, so the controller's watchdog
   knows the host is alive;
4. when the link ends: detach, tell the driver (``on_down``), and go back to 1.

A handshake that fails (a command unanswered, the port closed under it, any exception) or
takes longer than ``handshake_timeout_s`` fails the attempt, which is retried like a failed
open: a fault during reconnection leads to another reconnection, never to a dead link.  The
handshake runs as a task that every way out of an attempt cancels and awaits (stop included),
so no task outlives its attempt and no exception goes unretrieved; an unexpected exception
in the loop itself is logged and counts as a failed attempt.  The driver is told ``on_up``
only once the link is ready, so nothing says "connected" while moves are still refused.

Failed attempts wait as the shared :class:`robot.backoff.Backoff` says (the driver's: its
initial delay doubling up to its cap, each wait multiplied by a random factor in [0.5, 1], so
that the cells of a plant do not retry in step); a success resets the delay.  The first retry after losing a working link is
immediate.  The cap bounds how long a returned port goes unnoticed.  One warning is logged
when an outage starts and one info line when it ends, however many attempts it took.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Awaitable, Callable
from typing import Any

from robot.backoff import Backoff
from robot.drivers.serial.device import SerialDevice
from robot.drivers.serial.frames import Ping
from robot.drivers.serial.transport import SerialLink
from robot.errors import CommandTimeout, LinkDown, RobotError

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
    on_up : callable, optional
        Called once the handshake succeeded and :attr:`ready` is set (the driver publishes
        ``connected=True`` only then).
    heartbeat_s, silence_timeout_s : float
        Idle time before a ``PING``; silence after which the link is declared dead.
    command_timeout_s : float
        Timeout of the heartbeat ``PING``.
    handshake_timeout_s : float, optional
        Longest handshake; a slower one fails the attempt (default: five command timeouts).
    backoff : Backoff
        Waits between failed attempts (reset after every success).
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
        backoff: Backoff,
        on_up: Callable[[], None] | None = None,
        handshake_timeout_s: float | None = None,
    ) -> None:
        self.port = port
        self.baud = baud
        self.device = device
        self._handshake = handshake
        self._on_down = on_down
        self._on_up = on_up
        self.heartbeat_s = heartbeat_s
        self.silence_timeout_s = silence_timeout_s
        self.command_timeout_s = command_timeout_s
        self.handshake_timeout_s = (
            5.0 * command_timeout_s if handshake_timeout_s is None else handshake_timeout_s
        )
        if not self.handshake_timeout_s > 0:
            raise ValueError(
                f"handshake_timeout_s must be positive, got {self.handshake_timeout_s!r}"
            )
        self.backoff = backoff
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
        self._last_beat_s = 0.0
        self._rx_seen_s = 0.0
        self._stalled_s = 0.0

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
    async def _run(self) -> None:
        while True:
            try:
                was_up = await self._attempt()
            except Exception as exc:  # a bug below must not end supervision: log, try again
                log.exception("serial supervisor: unexpected error on %s", self.port)
                self._note_down(f"unexpected error: {type(exc).__name__}: {exc}")
                was_up = False
            if was_up:
                self.backoff.reset()  # a working link was lost: retry at once
            else:
                await self.backoff.sleep()

    async def _attempt(self) -> bool:
        """One connection: open, hand-shake, serve until lost.  True if it was ever ready.

        Every way out (a failed open, a failed or hung handshake, the link lost, an
        exception, cancellation by :meth:`stop`) leaves no task behind: the handshake is
        cancelled and awaited here, its exception retrieved.
        """
        try:
            link = await SerialLink.open(self.port, baud=self.baud, on_bytes=self.device.feed)
        except LinkDown as exc:
            self._note_down(str(exc))
            return False
        self.link = link
        self.device.attach(link)
        handshake = asyncio.create_task(self._bounded_handshake(), name="serial-handshake")
        up = False
        why = "port closed during the handshake"
        try:
            ends: set[asyncio.Future[Any]] = {handshake, link.closed}
            await asyncio.wait(ends, return_when=asyncio.FIRST_COMPLETED)
            if handshake.done() and not handshake.cancelled():
                error = handshake.exception()
                if error is not None:
                    why = f"handshake failed: {error}"
                else:
                    up = True
                    self.ready.set()
                    self.connected_at = time.monotonic()
                    self._note_up()
                    if self._on_up is not None:
                        self._on_up()
                    await link.closed
                    why = self._close_reason or f"serial link lost ({link.closed.result()})"
        finally:
            self.ready.clear()
            if not handshake.done():
                handshake.cancel()
            # Retrieve its outcome whatever it is (even while stop() cancels this task).
            await asyncio.gather(handshake, return_exceptions=True)
            self.device.detach()
            link.close()
            self.link = None
        self._close_reason = None
        self._note_down(why)
        return up

    async def _bounded_handshake(self) -> None:
        """The driver's handshake, failed if it takes longer than ``handshake_timeout_s``."""
        try:
            async with asyncio.timeout(self.handshake_timeout_s):
                await self._handshake()
        except TimeoutError:
            raise CommandTimeout(
                f"handshake not finished within {self.handshake_timeout_s:g} s"
            ) from None

    @property
    def _beat_interval_s(self) -> float:
        """How often the line is checked: half the heartbeat, so a ping is never late by more."""
        return self.heartbeat_s / 2

    async def _heartbeat(self) -> None:
        self._last_beat_s = time.monotonic()
        while True:
            await asyncio.sleep(self._beat_interval_s)
            try:
                self._beat()
            except Exception:  # never let the watch on the line die silently
                log.exception("serial supervisor: heartbeat failed on %s", self.port)

    def _beat(self) -> None:
        link = self.link
        now = time.monotonic()
        # Silence is counted in the host's own running time.  When this process is held up
        # (the GIL behind a long computation, swapping, a starved machine) the beat comes
        # late and no ping went out meanwhile, so the quiet of those seconds says nothing
        # about the controller: the lateness is discounted until something is received.
        late = now - self._last_beat_s - self._beat_interval_s
        self._last_beat_s = now
        if self.device.last_rx_s != self._rx_seen_s:
            self._rx_seen_s, self._stalled_s = self.device.last_rx_s, 0.0
        self._stalled_s += max(0.0, min(late, now - self.device.last_rx_s))
        if not self.ready.is_set() or link is None:
            return
        if now - self.device.last_rx_s - self._stalled_s > self.silence_timeout_s:
            self._close_reason = f"controller silent for {self.silence_timeout_s:g} s"
            link.close()
        elif now - self.device.last_tx_s >= self.heartbeat_s and (
            self._ping is None or self._ping.done()
        ):
            self._ping = asyncio.create_task(self._quiet_ping(), name="serial-ping")

    async def _quiet_ping(self) -> None:
        try:
            await self.device.request(lambda s: Ping(s), timeout_s=self.command_timeout_s)
        except RobotError:
            pass  # a lost ping is what silence detection is for
        except Exception:
            log.exception("serial supervisor: heartbeat ping failed on %s", self.port)

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
