"""``SerialDriver``: the :class:`~robot.drivers.base.RobotDriver` of an arm controller on a serial line.

Layers, bottom up: :mod:`.transport` (bytes, pyserial-asyncio), :mod:`.framing` (lines and
CRC), :mod:`.frames` (dataclasses), :mod:`.device` (commands matched to replies, window,
re-sends, timeouts, emergency-stop priority), and this module: the robot-level API plus a
supervisor task that keeps the link up.

Supervisor
    Opens the port, says ``HELLO`` with this driver's session id, sets the state-event rate,
    reads the controller's limits and state, then waits for the link to end.  When the port
    disappears or the controller falls silent for ``silence_timeout_s``, it publishes a state
    with ``connected=False`` and ``fault="disconnected: ..."``, logs one warning for the whole
    outage, and retries with the shared exponential backoff (:class:`robot.backoff.Backoff`:
    ``backoff_initial_s`` doubling up to
    ``backoff_max_s``, each wait multiplied by a random factor in [0.5, 1] so that several
    cells do not retry in step), back to the initial delay after a success.  The cap bounds
    the time to notice a returned port.  A resumed session (same controller boot, same
    session id) lets unanswered commands be re-sent with their sequence numbers.

Moves (same semantics as :class:`~robot.drivers.ideal.IdealDriver`)
    ``move`` raises when the arm certainly did not move: joint limits (checked with
    :func:`robot.model.check_joints` before anything is sent), link down, emergency stop
    active, another move running, a refusal by the controller, or a failure while the
    trajectory was being uploaded.  Once ``RUN`` may have reached the controller, ``move``
    returns a :class:`~robot.drivers.base.MoveReport`: ``completed=True`` only if the
    controller reported the move done.  If the link drops during a move, ``move`` waits up to
    ``reconnect_grace_s`` for the supervisor to reconnect and asks the controller what
    happened (``QMV``); if the link stays down it returns ``completed=False`` with
    ``reason="disconnected: ..."`` (the controller's watchdog stops an arm whose host has
    gone quiet).  A motion command is re-sent only with its own sequence number, and
    re-issued under a new number only after the controller said it never started it.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import random
import secrets
import time
from collections.abc import AsyncIterator, Callable
from dataclasses import replace

import numpy as np
from numpy.typing import ArrayLike

from robot.backoff import Backoff
from robot.drivers.base import GripReport, MoveReport, RobotState, StateHub, check_grip_flag
from robot.drivers.serial.device import SerialDevice
from robot.drivers.serial.frames import (
    PROTOCOL_VERSION,
    TERMINAL_STATUSES,
    Ack,
    ArmSnapshot,
    Command,
    DoneEvent,
    Event,
    GetLimits,
    GetState,
    Grip,
    Hello,
    HelloInfo,
    LimitsInfo,
    MoveJoints,
    MoveOutcome,
    Ping,
    QueryMove,
    Reset,
    Run,
    SetRate,
    StateEvent,
    Stop,
    TrajBegin,
    TrajPoint,
)
from robot.drivers.serial.supervisor import LinkSupervisor
from robot.errors import (
    CommandRejected,
    CommandSuperseded,
    CommandTimeout,
    DriverError,
    LinkDown,
    RobotBusy,
    RobotError,
)
from robot.model import ASEA, ArmModel, check_joints
from robot.trajectory import JointTrajectory

__all__ = ["SerialDriver"]

log = logging.getLogger(__name__)

_REASONS = {
    "DONE": "done",
    "STOPPED": "stopped",
    "ESTOP": "estop",
    "WATCHDOG": "link lost: the controller's watchdog stopped the arm",
}


def _positive(name: str, value: float) -> float:
    if not (value > 0 and math.isfinite(value)):
        raise ValueError(f"{name} must be a positive number, got {value!r}")
    return float(value)


class SerialDriver:
    """An arm controller reached over a serial line (``docs/serial-protocol.md``).

    Parameters
    ----------
    port : str
        Serial device path (``/dev/ttyUSB0``) or a stable symlink to one (the emulator's
        ``var/robot-tty``); re-resolved at every reconnection.
    baud : int
        Line speed, bit/s (8 data bits, no parity, 1 stop bit, no flow control).
    model : ArmModel
        Joint ranges for the limit gate (checked before anything is sent).
    state_rate_hz : float
        State-event rate asked of the controller.
    window : int
        Most commands unanswered at once (the controller may announce a smaller one).
    resend_after_s : float
        An unanswered command is re-sent, with the same sequence number, this often (plus
        the time the line needs at ``baud`` for the frames ahead of it and the reply).
    command_timeout_s : float
        Timeout of every command, from its first write.
    estop_timeout_s : float
        Timeout of the emergency stop (re-sent every 30 ms until acknowledged).
    heartbeat_s : float
        A ``PING`` goes out when nothing was sent for this long (feeds the watchdog).
    silence_timeout_s : float
        With nothing received for this long, the link is declared down and re-opened.
    connect_timeout_s : float
        How long :meth:`connect` waits for the first link (it keeps trying afterwards).
    reconnect_grace_s : float
        How long a running :meth:`move` waits for a lost link to come back.
    backoff_initial_s, backoff_max_s : float
        Reconnection backoff: first delay and cap.
    session_id : str, optional
        Eight upper-case hex digits naming this host's session (default: random).
    seed : int, optional
        Seed for the backoff jitter.
    """

    name = "serial"

    def __init__(
        self,
        port: str,
        *,
        baud: int = 115200,
        model: ArmModel = ASEA,
        state_rate_hz: float = 50.0,
        window: int = 8,
        resend_after_s: float = 0.2,
        command_timeout_s: float = 2.0,
        estop_timeout_s: float = 0.5,
        heartbeat_s: float = 0.2,
        silence_timeout_s: float = 1.0,
        connect_timeout_s: float = 3.0,
        reconnect_grace_s: float = 3.0,
        backoff_initial_s: float = 0.05,
        backoff_max_s: float = 0.5,
        session_id: str | None = None,
        seed: int | None = None,
    ) -> None:
        if not isinstance(port, str) or not port:
            raise ValueError(f"port must be a non-empty path, got {port!r}")
        if not isinstance(baud, int) or baud <= 0:
            raise ValueError(f"baud must be a positive integer, got {baud!r}")
        if not 0 <= state_rate_hz <= 250:
            raise ValueError(f"state_rate_hz must be in [0, 250], got {state_rate_hz!r}")
        if backoff_max_s < backoff_initial_s:
            raise ValueError(
                f"backoff_max_s ({backoff_max_s!r}) must be >= backoff_initial_s "
                f"({backoff_initial_s!r})"
            )
        if session_id is not None and (
            len(session_id) != 8 or any(c not in "0123456789ABCDEF" for c in session_id)
        ):
            raise ValueError(f"session_id must be 8 upper-case hex digits, got {session_id!r}")
        self.port = port
        self.baud = baud
        self.model = model
        self.state_rate_hz = float(state_rate_hz)
        self.window = int(window)
        self.resend_after_s = _positive("resend_after_s", resend_after_s)
        self.command_timeout_s = _positive("command_timeout_s", command_timeout_s)
        self.estop_timeout_s = _positive("estop_timeout_s", estop_timeout_s)
        self.heartbeat_s = _positive("heartbeat_s", heartbeat_s)
        self.silence_timeout_s = _positive("silence_timeout_s", silence_timeout_s)
        self.connect_timeout_s = _positive("connect_timeout_s", connect_timeout_s)
        self.reconnect_grace_s = _positive("reconnect_grace_s", reconnect_grace_s)
        self.backoff_initial_s = _positive("backoff_initial_s", backoff_initial_s)
        self.backoff_max_s = _positive("backoff_max_s", backoff_max_s)
        self.session_id = session_id or secrets.token_hex(4).upper()
        self.controller: HelloInfo | None = None
        """The controller's last ``HELLO`` answer (None before the first connection)."""
        self.limits: LimitsInfo | None = None
        """The controller's joint ranges, read at every connection."""
        self._rng = random.Random(seed)
        self._device = SerialDevice(
            self._on_event, window=window, resend_after_s=resend_after_s, baud=baud
        )
        self._hub = StateHub(
            RobotState(tuple(model.q_home), connected=False, fault="not connected")
        )
        self._hint = asyncio.Event()
        self._lock = asyncio.Lock()
        self._waiters: dict[int, asyncio.Future[MoveOutcome]] = {}
        self._epoch = 0
        self._boot_id: str | None = None
        self._last_stamp_ms = -1
        self._snap: ArmSnapshot | None = None
        self._warned_limits: LimitsInfo | None = None
        self._mid = 0
        self._background: set[asyncio.Task[None]] = set()
        self._sup = LinkSupervisor(
            port,
            baud=baud,
            device=self._device,
            handshake=self._handshake,
            on_down=self._on_down,
            on_up=self._on_up,
            heartbeat_s=self.heartbeat_s,
            silence_timeout_s=self.silence_timeout_s,
            command_timeout_s=self.command_timeout_s,
            backoff=Backoff(
                initial_s=self.backoff_initial_s, max_s=self.backoff_max_s, rng=self._rng
            ),
        )
        self._ready = self._sup.ready

    # -- RobotDriver protocol -----------------------------------------------------------------
    async def connect(self) -> None:
        """Start the supervisor and wait up to ``connect_timeout_s`` for the first link.

        Returns even if the controller is not reachable yet (the state then says
        ``connected=False`` and the supervisor keeps trying in the background).
        """
        self._sup.start()
        try:
            async with asyncio.timeout(self.connect_timeout_s):
                await self._ready.wait()
        except TimeoutError:
            log.warning("serial controller at %s not reachable yet; still trying", self.port)

    async def close(self) -> None:
        """Stop the supervisor, close the port, fail pending commands; idempotent."""
        await self._sup.stop()
        for t in list(self._background):
            t.cancel()
        await asyncio.gather(*self._background, return_exceptions=True)
        await self._device.close()
        self._hint.set()
        last = self._hub.latest
        self._hub.publish(
            replace(
                last,
                qd=(0.0,) * 5,
                stamp_s=time.monotonic(),
                connected=False,
                moving=False,
                fault="",
            )
        )

    @property
    def state(self) -> RobotState:
        """The latest state (never blocks); ``connected=False`` while the link is down."""
        return self._hub.latest

    def states(self) -> AsyncIterator[RobotState]:
        """Latest state first, then each new one (old ones dropped)."""
        return self._hub.stream()

    async def move(self, trajectory: JointTrajectory) -> MoveReport:
        """Stream ``trajectory`` to the controller, run it, and await its end.

        Raises
        ------
        JointLimitError
            A point lies outside the model's ranges (nothing was sent).
        LinkDown, CommandTimeout, CommandRejected, DriverError
            The move was not started (see the module docstring).
        RobotBusy
            Emergency stop active, another move running, or an emergency stop during upload.
        """
        check_joints(trajectory.q, self.model)
        n = int(trajectory.t_s.size)
        if self.controller is not None and n > self.controller.max_points:
            raise DriverError(
                f"trajectory has {n} points; the controller buffers at most "
                f"{self.controller.max_points}"
            )
        async with self._motion() as (mid, epoch):
            await self._upload(mid, trajectory)
            return await self._start_and_follow(mid, epoch, lambda s: Run(s, mid))

    async def move_joints(
        self, q_goal: ArrayLike, *, speed: float | None = None, duration_s: float | None = None
    ) -> MoveReport:
        """Point-to-point move planned by the controller (one ``MOVE`` frame).

        Parameters
        ----------
        q_goal : array_like of shape (5,)
            Target joints, radians (checked against the limits before sending).
        speed : float in (0, 1], optional
            Fraction of the speed limits; or
        duration_s : float, optional
            Duration of the move (not shorter than the fastest synchronised move).
        """
        q = check_joints(np.asarray(q_goal, dtype=np.float64).reshape(5), self.model)
        if (speed is None) == (duration_s is None):
            raise ValueError(
                f"give exactly one of speed and duration_s, got {speed!r}, {duration_s!r}"
            )
        goal = tuple(float(v) for v in q)
        async with self._motion() as (mid, epoch):
            return await self._start_and_follow(
                mid, epoch, lambda s: MoveJoints(s, mid, goal, duration_s, speed)
            )

    async def stop(self) -> None:
        """Controlled stop of the current move (the move reports ``"stopped"``)."""
        await self._cmd(lambda s: Stop(s))

    async def estop(self) -> None:
        """Emergency stop, ahead of every queued command.

        Raises
        ------
        LinkDown
            The link is down: the stop cannot be delivered (the controller's watchdog halts
            an arm whose host went quiet).
        CommandTimeout
            No acknowledgement within ``estop_timeout_s``.
        """
        await self._device.estop(timeout_s=self.estop_timeout_s)
        self._hub.publish(replace(self._hub.latest, estopped=True, stamp_s=time.monotonic()))

    async def reset(self) -> None:
        """Clear an emergency stop or a fault on the controller."""
        await self._cmd(lambda s: Reset(s))
        await self._refresh_state()

    # -- extra queries ------------------------------------------------------------------------
    async def grip(self, on: bool) -> GripReport:
        """Suction gripper on or off (``GRIP 1`` / ``GRIP 0``), within ``command_timeout_s``.

        Raises
        ------
        LinkDown
            The link is down (nothing sent).
        CommandTimeout
            No reply in time: whether the gripper switched is unknown (the next state
            event's ``G``/``H`` flags will tell).
        RobotBusy
            The controller refused it during an emergency stop.
        CommandRejected
            Any other refusal.
        """
        on = check_grip_flag(on)
        try:
            ack = await self._cmd(lambda s: Grip(s, on))
        except CommandRejected as exc:
            raise self._refusal(exc) from exc
        on_now, holding = Grip.parse_reply(ack.args)
        with contextlib.suppress(RobotError):
            await self._refresh_state()
        if on_now:
            detail = "part held" if holding else "suction on; no part held"
        else:
            detail = "suction off"
        return GripReport(on_now, holding, detail=detail)

    async def ping(self) -> float:
        """Round trip of one ``PING``, seconds."""
        t0 = time.perf_counter()
        await self._cmd(lambda s: Ping(s))
        return time.perf_counter() - t0

    async def query_limits(self) -> LimitsInfo:
        """Ask the controller for its joint ranges and speed limits."""
        ack = await self._cmd(lambda s: GetLimits(s))
        self.limits = LimitsInfo.from_args(ack.args)
        return self.limits

    async def query_move(self, mid: int) -> MoveOutcome:
        """Ask the controller what became of move ``mid`` (raises if it does not know it)."""
        ack = await self._cmd(lambda s: QueryMove(s, mid))
        return MoveOutcome.from_args(ack.args)

    @property
    def last_move_id(self) -> int:
        """Move id of the latest ``move``/``move_joints`` that got past the preconditions."""
        return self._mid

    @property
    def stats(self) -> dict[str, int]:
        """Counters of the command layer plus ``outages``."""
        d = dict(vars(self._device.stats))
        d["outages"] = self._sup.outages
        return d

    @property
    def outages(self) -> int:
        """Outages of the link so far (each logged once)."""
        return self._sup.outages

    @property
    def connected_at(self) -> float:
        """``time.monotonic()`` when the link was last (re-)established."""
        return self._sup.connected_at

    @property
    def last_outage_s(self) -> float:
        """Length of the last outage that ended, seconds."""
        return self._sup.last_outage_s

    # -- motion internals ---------------------------------------------------------------------
    @contextlib.asynccontextmanager
    async def _motion(self) -> AsyncIterator[tuple[int, int]]:
        if not self._ready.is_set():
            raise LinkDown(f"serial controller at {self.port} is not connected")
        if self.state.estopped:
            raise RobotBusy("emergency stop is active: reset before moving")
        if self._lock.locked():
            raise RobotBusy("a move is already executing")
        async with self._lock:
            self._mid += 1
            mid = self._mid
            self._waiters[mid] = asyncio.get_running_loop().create_future()
            try:
                yield mid, self._epoch
            finally:
                fut = self._waiters.pop(mid)
                if not fut.done():
                    fut.cancel()

    async def _cmd(self, make: Callable[[int], Command]) -> Ack:
        return await self._device.request(make, timeout_s=self.command_timeout_s)

    async def _upload(self, mid: int, traj: JointTrajectory) -> None:
        """Send TBEGIN and every point (pipelined); raises if anything fails: nothing moved."""
        n = int(traj.t_s.size)
        t, q, qd = traj.t_s, traj.q, traj.qd

        def point(i: int) -> Callable[[int], Command]:
            return lambda s: TrajPoint(
                s, mid, i, float(t[i]), tuple(map(float, q[i])), tuple(map(float, qd[i]))
            )

        tasks: list[asyncio.Task[Ack]] = []
        try:
            await self._cmd(lambda s: TrajBegin(s, mid, n))
            # Keep about two windows of points submitted; the device queue keeps their order.
            pending: set[asyncio.Task[Ack]] = set()
            for i in range(n):
                while len(pending) >= 2 * self._device.window:
                    done, pending = await asyncio.wait(pending, return_when=asyncio.FIRST_COMPLETED)
                    for d in done:
                        d.result()
                task = asyncio.create_task(self._cmd(point(i)))
                tasks.append(task)
                pending.add(task)
            for fut in asyncio.as_completed(pending):
                await fut
        except CommandSuperseded as exc:
            raise RobotBusy(f"emergency stop during upload: move {mid} was not started") from exc
        except CommandRejected as exc:
            raise self._refusal(exc) from exc
        except (LinkDown, CommandTimeout) as exc:
            raise type(exc)(
                f"upload of move {mid} failed, the move was not started: {exc}"
            ) from exc
        finally:
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)

    @staticmethod
    def _refusal(exc: CommandRejected) -> RobotError:
        if exc.nak_code in ("BUSY", "ESTOP"):
            return RobotBusy(str(exc))
        return exc

    async def _start_and_follow(
        self, mid: int, epoch: int, make: Callable[[int], Command]
    ) -> MoveReport:
        try:
            try:
                outcome = MoveOutcome.from_args((await self._cmd(make)).args)
            except CommandRejected as exc:
                raise self._refusal(exc) from exc
            except CommandSuperseded as exc:
                if not exc.sent:
                    raise RobotBusy(f"emergency stop before move {mid} started") from exc
                outcome = await self._resolve(mid, epoch, None)
            except DriverError:  # timeout, link lost, unreadable reply: fate unknown
                outcome = await self._resolve(mid, epoch, make)
            if not outcome.terminal:
                outcome = await self._follow(mid, epoch)
        except asyncio.CancelledError:
            self._stop_in_background()
            raise
        await self._settle(outcome)
        if outcome.status in _REASONS:
            reason = _REASONS[outcome.status]
        elif outcome.status == "DISCARDED":
            reason = f"not started: {outcome.reason}"
        else:
            reason = outcome.reason or "fault"
        return MoveReport(
            completed=outcome.status == "DONE",
            reason=reason,
            duration_s=outcome.duration_s,
            final_q=outcome.q,
            final_error_rad=outcome.error_rad,
        )

    async def _settle(self, outcome: MoveOutcome) -> None:
        """Make :attr:`state` show where the move ended before ``move`` returns."""
        if self._ready.is_set():
            with contextlib.suppress(RobotError):
                await self._refresh_state()
                return
        if math.isfinite(outcome.error_rad):  # a real controller answer, not a lost link
            self._hub.publish(
                replace(self._hub.latest, q=outcome.q, qd=(0.0,) * 5, stamp_s=time.monotonic())
            )

    def _lost(self, mid: int, why: str) -> MoveOutcome:
        q = self._hub.latest.q
        return MoveOutcome(mid, "FAULT", 0.0, q, float("nan"), why)

    async def _resolve(
        self, mid: int, epoch: int, reissue: Callable[[int], Command] | None
    ) -> MoveOutcome:
        """The start command's fate is unknown: ask, and re-issue only if it never ran."""
        for _ in range(4):
            if not await self._wait_ready():
                return self._lost(mid, "disconnected: link down, outcome of the move unknown")
            if self._epoch != epoch:
                return self._lost(mid, "controller restarted; outcome of the move unknown")
            try:
                known: MoveOutcome | None = await self.query_move(mid)
            except CommandRejected as exc:
                if exc.nak_code != "UNKNOWN_MOVE":
                    continue
                known = None
            except RobotError:  # no answer, link lost, overtaken by an e-stop: ask again
                continue
            if known is not None and known.status != "LOADING":
                return known
            # Confirmed by the controller: this move never started, so a new number is safe.
            if reissue is None:
                return self._lost(mid, "emergency stop before the move started")
            try:
                return MoveOutcome.from_args((await self._cmd(reissue)).args)
            except CommandRejected as exc:
                return self._lost(mid, f"refused: {exc}")
            except RobotError:
                continue
        return self._lost(mid, "could not learn the outcome of the move")

    async def _follow(self, mid: int, epoch: int) -> MoveOutcome:
        """Wait for the move's terminal status: DONE event, state hint or polling."""
        fut = self._waiters[mid]
        while True:
            if fut.done():
                return fut.result()
            self._hint.clear()
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(0.5):
                    await self._hint.wait()
            if fut.done():
                return fut.result()
            if not self._ready.is_set() and not await self._wait_ready():
                return self._lost(mid, "disconnected: serial link lost during the move")
            if self._epoch != epoch:
                return self._lost(mid, "controller restarted during the move")
            try:
                known = await self.query_move(mid)
            except CommandRejected as exc:
                if exc.nak_code == "UNKNOWN_MOVE":
                    return self._lost(mid, "controller no longer knows the move")
                continue
            except RobotError:
                continue
            if known.terminal:
                return known

    async def _wait_ready(self) -> bool:
        return await self._sup.wait_ready(self.reconnect_grace_s)

    def _stop_in_background(self) -> None:
        async def stop() -> None:
            with contextlib.suppress(RobotError):
                await self.stop()

        if self._ready.is_set():
            task = asyncio.get_running_loop().create_task(stop())
            self._background.add(task)
            task.add_done_callback(self._background.discard)

    # -- supervisor ---------------------------------------------------------------------------
    async def _handshake(self) -> None:
        ack = await self._device.request(
            lambda s: Hello(s, self.session_id), timeout_s=self.command_timeout_s, urgent=True
        )
        info = HelloInfo.from_args(ack.args)
        if info.version != PROTOCOL_VERSION:
            raise DriverError(f"controller speaks protocol {info.version}, not {PROTOCOL_VERSION}")
        resumed = info.resumed and info.boot_id == self._boot_id
        if self._boot_id is not None and not resumed:
            self._epoch += 1
            log.warning(
                "serial controller at %s started a new session (%s); "
                "unanswered commands are abandoned",
                self.port,
                "it restarted" if info.boot_id != self._boot_id else "session lost",
            )
        if info.boot_id != self._boot_id:
            self._last_stamp_ms = -1  # a new controller clock
        self._snap = None
        self._boot_id = info.boot_id
        self.controller = info
        self._device.window = max(1, min(self.window, info.window))
        self._device.set_ready(resumed=resumed)
        await self._cmd(lambda s: SetRate(s, self.state_rate_hz))
        limits = await self.query_limits()
        narrower = (np.asarray(limits.lower) > self.model.lower + 1e-6) | (
            np.asarray(limits.upper) < self.model.upper - 1e-6
        )
        if narrower.any() and limits != self._warned_limits:
            self._warned_limits = limits
            log.warning(
                "controller at %s has narrower joint ranges than the model on %s; "
                "it will refuse moves outside them",
                self.port,
                ", ".join(f"q{j + 1}" for j in np.flatnonzero(narrower)),
            )
        await self._refresh_state()

    async def _refresh_state(self) -> None:
        ack = await self._cmd(lambda s: GetState(s))
        self._publish(ArmSnapshot.from_args(ack.args))

    def _on_down(self, why: str) -> None:
        """The supervisor lost the link (or failed to get one): show it, wake waiting moves."""
        last = self._hub.latest
        self._hub.publish(
            RobotState(
                q=last.q,
                stamp_s=time.monotonic(),
                connected=False,
                moving=False,
                estopped=last.estopped,
                fault=f"disconnected: {why}",
            )
        )
        self._hint.set()

    # -- events -------------------------------------------------------------------------------
    def _on_event(self, event: Event) -> None:
        if isinstance(event, StateEvent):
            self._publish(event.state)
            if event.state.mid in self._waiters and event.state.move_status in TERMINAL_STATUSES:
                self._hint.set()
        elif isinstance(event, DoneEvent):
            fut = self._waiters.get(event.outcome.mid)
            if fut is not None and not fut.done():
                fut.set_result(event.outcome)
            self._hint.set()

    def _publish(self, snap: ArmSnapshot) -> None:
        """Show ``snap``, but only once the link is ready (the handshake finished).

        A reply that arrives during a handshake (a command re-sent on a resumed session)
        is kept for :meth:`_on_up`: publishing it would say ``connected=True`` while moves
        are still refused, and the handshake may yet fail.
        """
        if snap.stamp_ms < self._last_stamp_ms:
            return  # older than what we already showed (a reply overtook a delayed event)
        self._last_stamp_ms = snap.stamp_ms
        self._snap = snap
        if self._ready.is_set():
            self._show(snap)

    def _show(self, snap: ArmSnapshot) -> None:
        self._hub.publish(
            RobotState(
                q=snap.q,
                qd=snap.qd,
                stamp_s=time.monotonic(),
                connected=True,
                moving=snap.moving,
                estopped=snap.estopped,
                fault=snap.fault,
                gripper_on=snap.gripper_on,
                holding=snap.holding,
            )
        )

    def _on_up(self) -> None:
        """The supervisor's link is ready: publish the state read by the handshake."""
        if self._snap is not None:
            self._show(self._snap)
        self._hint.set()
