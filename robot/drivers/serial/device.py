"""Async device API of the controller link: commands, replies matched by sequence number.

:class:`SerialDevice` sits on top of a :class:`~robot.drivers.serial.transport.SerialLink`
(bytes) and :mod:`~robot.drivers.serial.frames` (frames).  It owns the host's side of the
rules in ``docs/serial-protocol.md`` section 5:

* every command gets the next sequence number and a future; the reply with the same number
  resolves it (a reply nobody waits for any more is counted and dropped);
* at most ``window`` commands are unanswered at once; later ones wait in a FIFO queue;
* every command has a timeout (``asyncio.timeout``), counted from its first write;
* an unanswered command is re-sent with the SAME sequence number every ``resend_after_s``
  (counted after the time the line needs, at ``baud``, to carry the unanswered frames ahead
  of it, the command itself and a reply, so a slow line does not cause needless re-sends):
  the controller answers a repeated number from its reply cache without executing the
  command again, so a re-send is safe for every command, motion included.  A command is
  never re-issued under a new number here; the driver does that only after the controller
  confirmed that the first one did not run;
* the emergency stop overtakes everything: queued commands are failed (never sent), the
  bytes not yet on the wire are dropped, and the stop frame goes out at once;
* when the link drops, commands not yet written fail at once with :class:`LinkDown`;
  written ones stay pending and are re-sent with their number once the driver has resumed
  the same controller session, or fail if the controller started a new one.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

from robot.drivers.serial.frames import (
    Ack,
    Command,
    EStop,
    Event,
    Frame,
    FrameParser,
    Nak,
    encode,
)
from robot.drivers.serial.transport import SerialLink
from robot.errors import (
    CommandRejected,
    CommandSuperseded,
    CommandTimeout,
    LinkDown,
    ProtocolError,
)

__all__ = ["DeviceStats", "SerialDevice"]

_REPLY_BYTES = 40  # a typical acknowledgement line, for the wire-time allowance


@dataclass
class DeviceStats:
    """Counters of one :class:`SerialDevice` (mutable, for logs and benchmarks).

    Attributes
    ----------
    commands : int
        Commands submitted.
    writes : int
        Frames written, first sends and re-sends.
    resends : int
        Re-sends of an unanswered command with its sequence number.
    replies : int
        Replies matched to a waiting command.
    late_replies : int
        Replies to commands that were already answered, timed out or abandoned.
    naks : int
        Negative acknowledgements received.
    timeouts : int
        Commands that got no reply in time.
    rejected_lines : int
        Received lines dropped for a bad checksum or grammar.
    events : int
        Controller events received.
    events_missed : int
        Gaps in the controller's event numbers (events lost on the line).
    """

    commands: int = 0
    writes: int = 0
    resends: int = 0
    replies: int = 0
    late_replies: int = 0
    naks: int = 0
    timeouts: int = 0
    rejected_lines: int = 0
    events: int = 0
    events_missed: int = 0


@dataclass(eq=False)
class _Pending:
    command: Command
    wire: bytes
    future: asyncio.Future[Ack | Nak]
    resend_after_s: float
    sent: asyncio.Event = field(default_factory=asyncio.Event)
    last_write: float = 0.0
    writes: int = 0
    wire_s: float = 0.0


def _fail(p: _Pending, exc: Exception) -> None:
    """Fail ``p`` and wake its waiter, whether or not it was ever written."""
    if not p.future.done():
        p.future.set_exception(exc)
    p.sent.set()


class SerialDevice:
    """Command/response correlation over one controller link at a time.

    Parameters
    ----------
    on_event : callable
        Called with every :class:`~robot.drivers.serial.frames.Event` received.
    window : int
        Most commands unanswered at once (the controller announces its own limit in
        ``HELLO``; the driver uses the smaller).
    resend_after_s : float
        Default interval after which an unanswered command is re-sent with its number.
    baud : int, optional
        Line speed, to add the wire time of the frames ahead to each re-send interval
        (``None``: no allowance).
    clock : callable
        Monotonic clock in seconds.
    """

    def __init__(
        self,
        on_event: Callable[[Event], None],
        *,
        window: int = 8,
        resend_after_s: float = 0.2,
        baud: int | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if window < 1:
            raise ValueError(f"window must be >= 1, got {window!r}")
        if not resend_after_s > 0:
            raise ValueError(f"resend_after_s must be positive, got {resend_after_s!r}")
        self.window = int(window)
        self.resend_after_s = float(resend_after_s)
        self._byte_s = 0.0 if baud is None else 10.0 / baud  # 8N1: 10 bit times per byte
        self.stats = DeviceStats()
        self._on_event = on_event
        self._clock = clock
        self._parser = FrameParser(on_reject=self._rejected)
        self._seq = 0
        self._queue: deque[_Pending] = deque()
        self._inflight: dict[int, _Pending] = {}
        self._link: SerialLink | None = None
        self._ready = False
        self._last_eseq: int | None = None
        self._resender: asyncio.Task[None] | None = None
        self.last_rx_s = 0.0
        self.last_tx_s = 0.0

    # -- link management (called by the driver's supervisor) ----------------------------------
    @property
    def ready(self) -> bool:
        """True while a link is attached and its session is established."""
        return self._ready and self._link is not None and self._link.is_open

    def feed(self, data: bytes) -> None:
        """Bytes received from the link (the link's ``on_bytes`` sink)."""
        self.last_rx_s = self._clock()
        for frame in self._parser.feed(data):
            self._dispatch(frame)

    def attach(self, link: SerialLink) -> None:
        """Use ``link`` for writing; not ready for queued commands until :meth:`set_ready`."""
        self._link = link
        self._ready = False
        self._parser.clear()
        self.last_rx_s = self._clock()
        if self._resender is None or self._resender.done():
            self._resender = asyncio.create_task(self._resend_loop(), name="serial-resend")

    def detach(self) -> None:
        """The link is gone: fail commands never written; keep written ones pending."""
        self._link = None
        self._ready = False
        while self._queue:
            _fail(
                self._queue.popleft(), LinkDown("serial link dropped before the command was sent")
            )

    def set_ready(self, *, resumed: bool) -> None:
        """The session is established: re-send or fail pending commands, then send queued ones.

        Parameters
        ----------
        resumed : bool
            True if the controller resumed the session these commands were sent in (its
            reply cache still knows them), so they are re-sent with their numbers.  False if
            it started a new one: their outcome cannot be learnt by re-sending, so they fail
            with :class:`LinkDown` and the caller must query.
        """
        self._ready = True
        for seq, p in list(self._inflight.items()):
            if resumed:
                self._write(p)
                self.stats.resends += 1
            else:
                del self._inflight[seq]
                _fail(p, LinkDown("controller started a new session; command outcome unknown"))
        self._pump()

    async def close(self) -> None:
        """Fail everything pending and stop the re-send timer."""
        self.fail_all(LinkDown("serial driver closed"))
        self._link = None
        self._ready = False
        if self._resender is not None:
            self._resender.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._resender
            self._resender = None

    def fail_all(self, exc: Exception) -> None:
        """Fail every queued and unanswered command with ``exc``."""
        for p in [*self._queue, *self._inflight.values()]:
            _fail(p, exc)
        self._queue.clear()
        self._inflight.clear()

    # -- commands -----------------------------------------------------------------------------
    def next_seq(self) -> int:
        """Take the next sequence number."""
        self._seq += 1
        return self._seq

    async def request(
        self,
        make: Callable[[int], Command],
        *,
        timeout_s: float,
        resend_after_s: float | None = None,
        urgent: bool = False,
    ) -> Ack:
        """Send the command built by ``make(seq)`` and wait for its acknowledgement.

        Parameters
        ----------
        make : callable
            Builds the command from its sequence number, e.g. ``lambda s: Ping(s)``.
        timeout_s : float
            Longest wait for the reply, counted from the command's first write (from the
            call for an urgent command, which is never queued).
        resend_after_s : float, optional
            Re-send interval for this command (default: the device's).
        urgent : bool
            Bypass the window and the queue (``HELLO`` during a handshake).  Emergency stops
            use :meth:`estop`.

        Returns
        -------
        Ack

        Raises
        ------
        LinkDown
            The link is down (nothing sent), or dropped before the command was written.
        CommandTimeout
            No reply within ``timeout_s``; the command may or may not have run.
        CommandRejected
            The controller answered NAK: the command did not run.
        CommandSuperseded
            An emergency stop overtook the command.
        """
        if not timeout_s > 0:
            raise ValueError(f"timeout_s must be positive, got {timeout_s!r}")
        if self._link is None or not self._link.is_open or not (self._ready or urgent):
            raise LinkDown("serial link is down")
        cmd = make(self.next_seq())
        loop = asyncio.get_running_loop()
        p = _Pending(cmd, encode(cmd), loop.create_future(), resend_after_s or self.resend_after_s)
        self.stats.commands += 1
        if urgent:
            self._inflight[cmd.seq] = p
            self._write(p)
            p.sent.set()  # its clock runs from now, even if the write did not go out
        else:
            self._queue.append(p)
            self._pump()
        return await self._await(p, timeout_s)

    async def estop(self, *, timeout_s: float, resend_after_s: float = 0.03) -> Ack:
        """Emergency stop ahead of every other command (see the module docstring).

        Raises
        ------
        LinkDown
            No link: the stop cannot be delivered (the controller's watchdog stops the arm).
        CommandTimeout
            No acknowledgement within ``timeout_s`` despite re-sends.
        """
        if self._link is None or not self._link.is_open:
            raise LinkDown("serial link is down: emergency stop not delivered")
        for p in self._queue:
            _fail(p, CommandSuperseded("dropped by an emergency stop before sending", sent=False))
        self._queue.clear()
        for p in self._inflight.values():
            _fail(p, CommandSuperseded("overtaken by an emergency stop; may have run", sent=True))
        self._inflight.clear()
        cmd = EStop(self.next_seq())
        loop = asyncio.get_running_loop()
        p = _Pending(cmd, encode(cmd), loop.create_future(), resend_after_s)
        self.stats.commands += 1
        self._inflight[cmd.seq] = p
        self._link.write_urgent(p.wire)
        self._mark_written(p)
        return await self._await(p, timeout_s)

    async def _await(self, p: _Pending, timeout_s: float) -> Ack:
        try:
            async with asyncio.timeout(None) as deadline:
                await p.sent.wait()
                deadline.reschedule(asyncio.get_running_loop().time() + timeout_s)
                reply = await p.future
        except TimeoutError:
            self.stats.timeouts += 1
            raise CommandTimeout(
                f"no reply to {p.command.VERB} (seq {p.command.seq}) within {timeout_s:g} s"
            ) from None
        finally:
            self._forget(p)
        if isinstance(reply, Nak):
            raise CommandRejected(reply.code, reply.detail)
        return reply

    # -- internals ----------------------------------------------------------------------------
    def _forget(self, p: _Pending) -> None:
        if self._inflight.get(p.command.seq) is p:
            del self._inflight[p.command.seq]
        with contextlib.suppress(ValueError):
            self._queue.remove(p)
        if not p.future.done():
            p.future.cancel()
        self._pump()

    def _pump(self) -> None:
        while self._queue and self.ready and len(self._inflight) < self.window:
            p = self._queue.popleft()
            if p.future.done():
                continue
            self._inflight[p.command.seq] = p
            self._write(p)

    def _write(self, p: _Pending) -> None:
        if self._link is None or not self._link.is_open:
            return
        try:
            self._link.write(p.wire)
        except LinkDown:
            return
        self._mark_written(p)

    def _mark_written(self, p: _Pending) -> None:
        if p.writes == 0:  # how long the line needs before an answer can be back
            ahead = sum(len(q.wire) for q in self._inflight.values() if q is not p and q.writes)
            p.wire_s = (ahead + len(p.wire) + _REPLY_BYTES) * self._byte_s
        p.writes += 1
        self.stats.writes += 1
        p.last_write = self.last_tx_s = self._clock()
        p.sent.set()

    async def _resend_loop(self) -> None:
        while True:
            await asyncio.sleep(min(self.resend_after_s, 0.03) / 2)
            if self._link is None or not self._link.is_open or not self._ready:
                continue
            now = self._clock()
            for p in list(self._inflight.values()):
                if p.sent.is_set() and now - p.last_write >= p.resend_after_s + p.wire_s:
                    self.stats.resends += 1
                    self._write(p)

    def _dispatch(self, frame: Frame) -> None:
        if isinstance(frame, Ack | Nak):
            p = self._inflight.get(frame.seq)
            if p is None or p.future.done():
                self.stats.late_replies += 1
                return
            self.stats.replies += 1
            if isinstance(frame, Nak):
                self.stats.naks += 1
            p.future.set_result(frame)
        elif isinstance(frame, Event):
            self.stats.events += 1
            if self._last_eseq is not None and frame.eseq > self._last_eseq + 1:
                self.stats.events_missed += frame.eseq - self._last_eseq - 1
            self._last_eseq = frame.eseq
            self._on_event(frame)
        # A command frame arriving at the host is noise (an echoing line); ignore it.

    def _rejected(self, exc: ProtocolError) -> None:
        self.stats.rejected_lines += 1
