"""The controller's move table: loading, starting and tracking moves by id, at most once each.

Used by the emulator (:mod:`robot.drivers.serial.emulator`) for the motion commands of the protocol
(``docs/serial-protocol.md`` section 6): ``TBEGIN``/``TP``/``RUN`` (a streamed trajectory),
``MOVE`` (a joint move planned here) and ``QMV`` (what became of a move).  Each move id of a
session is started at most once: a second ``RUN`` or ``MOVE`` for a known id is answered with
the move's current outcome and changes nothing.  Motion is carried out by any
:class:`~robot.drivers.base.RobotDriver`; every start is appended to :attr:`MoveTable.executions`,
the log that tests and the benchmark compare with what the host believes.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from robot.drivers.base import RobotDriver
from robot.drivers.serial.frames import (
    Ack,
    Command,
    MoveJoints,
    MoveOutcome,
    Nak,
    QueryMove,
    Run,
    TrajBegin,
    TrajPoint,
)
from robot.model import ArmModel
from robot.trajectory import JointTrajectory, plan_joint_move

__all__ = ["ExecutionRecord", "MoveTable"]

WIRE_TOL_RAD = 1e-6
"""Values travel with six decimals: a range end may arrive this far outside (then clipped)."""

_MAX_MOVES = 256


@dataclass(frozen=True)
class ExecutionRecord:
    """One motion actually handed to the backing driver.

    Attributes
    ----------
    session : str
        Host session id the move belongs to.
    mid : int
        Move id chosen by the host.
    kind : str
        ``"TRAJ"`` (streamed trajectory) or ``"MOVE"`` (joint move planned by the controller).
    n_points : int
        Points of the executed trajectory.
    started_s : float
        ``time.monotonic()`` when execution began.
    """

    session: str
    mid: int
    kind: str
    n_points: int
    started_s: float


@dataclass(eq=False)
class _Move:
    mid: int
    n_points: int
    status: str = "LOADING"
    t: np.ndarray | None = None
    q: np.ndarray | None = None
    qd: np.ndarray | None = None
    have: np.ndarray | None = None
    goal: tuple[float, ...] = ()
    started: float = 0.0
    outcome: MoveOutcome | None = None
    task: asyncio.Task[None] | None = None
    watchdog: bool = False


class MoveTable:
    """Moves of the current session, keyed by the host's move id.

    Parameters
    ----------
    driver : RobotDriver
        Carries out the motion.
    model : ArmModel
        Joint ranges enforced on every received point and target.
    max_points : int
        Largest trajectory accepted.
    start_tolerance_rad : float
        Largest distance between a trajectory's first point and the arm.
    estopped : callable
        True while the controller's emergency stop is latched.
    on_done : callable
        Called with ``(session, outcome)`` when a move reaches a terminal status.
    watchdog_s : float
        Reported in the reason of moves stopped by the link watchdog.
    """

    def __init__(
        self,
        driver: RobotDriver,
        *,
        model: ArmModel,
        max_points: int,
        start_tolerance_rad: float,
        estopped: Callable[[], bool],
        on_done: Callable[[str, MoveOutcome], None],
        watchdog_s: float,
    ) -> None:
        self.driver = driver
        self.model = model
        self.max_points = max_points
        self.start_tolerance_rad = start_tolerance_rad
        self._estopped = estopped
        self._on_done = on_done
        self.watchdog_s = watchdog_s
        self.executions: list[ExecutionRecord] = []
        self.session = ""
        self._moves: dict[int, _Move] = {}
        self._last_mid = 0
        self._active: _Move | None = None

    # -- session-level operations -------------------------------------------------------------
    def new_session(self, session: str) -> None:
        """Forget the previous session's moves (a running one goes on, reported to nobody)."""
        self.session = session
        self._moves.clear()
        self._last_mid = 0

    @property
    def moving(self) -> bool:
        """True while a started move has not ended."""
        return self._active is not None

    def latest(self) -> tuple[int, str]:
        """``(mid, status)`` of this session's latest move, ``(0, "NONE")`` if none."""
        m = self._moves.get(self._last_mid)
        return (m.mid, m.status) if m is not None else (0, "NONE")

    def discard_loading(self, reason: str) -> None:
        """Drop trajectories still being loaded (after an emergency stop)."""
        for m in self._moves.values():
            if m.status == "LOADING":
                self._set_outcome(m, "DISCARDED", reason)

    def trip_watchdog(self) -> int | None:
        """Mark the running move as stopped by the watchdog; its id, or None if none/done."""
        m = self._active
        if m is None or m.watchdog:
            return None
        m.watchdog = True
        return m.mid

    async def close(self) -> None:
        """Cancel the running move's task (the backing driver stops following it)."""
        m = self._active
        if m is not None and m.task is not None:
            m.task.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await m.task

    # -- commands -----------------------------------------------------------------------------
    def handle(self, cmd: Command) -> Ack | Nak:
        """Answer one motion-related command (``TBEGIN``, ``TP``, ``RUN``, ``MOVE``, ``QMV``)."""
        if isinstance(cmd, TrajBegin):
            return self._begin(cmd)
        if isinstance(cmd, TrajPoint):
            return self._point(cmd)
        if isinstance(cmd, Run):
            return self._run(cmd)
        if isinstance(cmd, MoveJoints):
            return self._move_joints(cmd)
        if isinstance(cmd, QueryMove):
            m = self._moves.get(cmd.mid)
            if m is None:
                return Nak(cmd.seq, "UNKNOWN_MOVE", f"no move {cmd.mid} in this session")
            return Ack(cmd.seq, "QMV", tuple(self._outcome(m).to_args()))
        raise ValueError(f"cmd must be a motion command, got {cmd.VERB!r}")

    def _begin(self, cmd: TrajBegin) -> Ack | Nak:
        m = self._moves.get(cmd.mid)
        if m is not None:
            if m.status == "LOADING" and m.n_points == cmd.n_points:
                return Ack(cmd.seq, "TBEGIN", (str(cmd.mid), str(cmd.n_points)))
            return Nak(cmd.seq, "USED", f"move id {cmd.mid} is {m.status}")
        if not 1 <= cmd.n_points <= self.max_points:
            return Nak(cmd.seq, "TRAJ", f"n_points must be in [1, {self.max_points}]")
        if self._estopped():
            return Nak(cmd.seq, "ESTOP", "emergency stop active: RESET first")
        self.discard_loading(f"replaced by move {cmd.mid}")
        n = cmd.n_points
        m = _Move(cmd.mid, n, t=np.zeros(n), q=np.zeros((n, 5)), qd=np.zeros((n, 5)))
        m.have = np.zeros(n, dtype=bool)
        self._remember(m)
        return Ack(cmd.seq, "TBEGIN", (str(cmd.mid), str(n)))

    def _point(self, cmd: TrajPoint) -> Ack | Nak:
        m = self._moves.get(cmd.mid)
        if m is None:
            return Nak(cmd.seq, "UNKNOWN_MOVE", f"no move {cmd.mid}: TBEGIN first")
        if m.status != "LOADING":
            return Nak(cmd.seq, "USED", f"move {cmd.mid} is {m.status}")
        if cmd.index >= m.n_points:
            return Nak(cmd.seq, "TRAJ", f"index {cmd.index} >= n_points {m.n_points}")
        q, nak = self._gate(cmd.seq, np.asarray(cmd.q), f"point {cmd.index}")
        if nak is not None:
            return nak
        assert m.t is not None and m.q is not None and m.qd is not None and m.have is not None
        m.t[cmd.index], m.q[cmd.index], m.qd[cmd.index] = cmd.t_s, q, cmd.qd
        m.have[cmd.index] = True
        return Ack(cmd.seq, "TP", (str(cmd.mid), str(cmd.index), str(int(m.have.sum()))))

    def _run(self, cmd: Run) -> Ack | Nak:
        m = self._moves.get(cmd.mid)
        if m is None:
            return Nak(cmd.seq, "UNKNOWN_MOVE", f"no move {cmd.mid} in this session")
        if m.status != "LOADING":  # already started once: report it, never run it twice
            return Ack(cmd.seq, "RUN", tuple(self._outcome(m).to_args()))
        assert m.have is not None and m.t is not None
        if not m.have.all():
            missing = int((~m.have).sum())
            return Nak(cmd.seq, "INCOMPLETE", f"{missing} of {m.n_points} points missing")
        refused = self._refuse(cmd.seq)
        if refused is not None:
            return refused
        try:
            if abs(float(m.t[0])) > 1e-9:
                raise ValueError("the first point must be at t = 0")
            traj = JointTrajectory(m.t, m.q, m.qd)  # type: ignore[arg-type]
        except ValueError as exc:
            return Nak(cmd.seq, "TRAJ", str(exc))
        nak = self._check_start(cmd.seq, traj)
        if nak is not None:
            return nak
        self._start(m, traj, "TRAJ")
        return Ack(cmd.seq, "RUN", tuple(self._outcome(m).to_args()))

    def _move_joints(self, cmd: MoveJoints) -> Ack | Nak:
        m = self._moves.get(cmd.mid)
        if m is not None:  # this move id was seen: report it, never run it twice
            return Ack(cmd.seq, "MOVE", tuple(self._outcome(m).to_args()))
        refused = self._refuse(cmd.seq)
        if refused is not None:
            return refused
        goal, nak = self._gate(cmd.seq, np.asarray(cmd.q), "target")
        if nak is not None:
            return nak
        q0 = np.asarray(self.driver.state.q, dtype=np.float64)
        try:
            if cmd.speed is not None:
                traj = plan_joint_move(q0, goal, speed=cmd.speed, model=self.model)
            else:
                assert cmd.duration_s is not None
                traj = plan_joint_move(q0, goal, model=self.model)
                if cmd.duration_s < traj.duration_s - 1e-9:
                    raise ValueError(
                        f"duration {cmd.duration_s:g} s is shorter than the fastest "
                        f"synchronised move, {traj.duration_s:.4f} s"
                    )
                if traj.t_s.size > 1:  # stretch in time: speeds / k, accelerations / k^2
                    k = cmd.duration_s / traj.duration_s
                    traj = JointTrajectory(traj.t_s * k, traj.q, traj.qd / k)
        except ValueError as exc:
            return Nak(cmd.seq, "TRAJ", str(exc))
        m = _Move(cmd.mid, int(traj.t_s.size))
        self._remember(m)
        self._start(m, traj, "MOVE")
        return Ack(cmd.seq, "MOVE", tuple(self._outcome(m).to_args()))

    # -- checks -------------------------------------------------------------------------------
    def _refuse(self, seq: int) -> Nak | None:
        st = self.driver.state
        if self._estopped() or st.estopped:
            return Nak(seq, "ESTOP", "emergency stop active: RESET first")
        if self._active is not None:
            return Nak(seq, "BUSY", f"move {self._active.mid} is executing")
        if st.fault or not st.connected:
            return Nak(seq, "FAULT", st.fault or "arm not connected")
        return None

    def _gate(self, seq: int, q: np.ndarray, what: str) -> tuple[np.ndarray, Nak | None]:
        lo, hi = self.model.lower, self.model.upper
        bad = np.argwhere((q < lo - WIRE_TOL_RAD) | (q > hi + WIRE_TOL_RAD))
        if bad.size:
            j = int(bad[0][-1])
            return q, Nak(
                seq,
                "LIMIT",
                f"{what} q{j + 1}={float(q[j]):.6f} outside [{lo[j]:.6f}, {hi[j]:.6f}]",
            )
        return np.clip(q, lo, hi), None

    def _check_start(self, seq: int, traj: JointTrajectory) -> Nak | None:
        gap = float(np.abs(traj.start - np.asarray(self.driver.state.q)).max())
        if gap > self.start_tolerance_rad:
            return Nak(
                seq,
                "START",
                f"first point is {gap:.4g} rad from the arm "
                f"(tolerance {self.start_tolerance_rad:g} rad)",
            )
        return None

    # -- execution ----------------------------------------------------------------------------
    def _start(self, m: _Move, traj: JointTrajectory, kind: str) -> None:
        m.status = "RUNNING"
        m.goal = tuple(float(v) for v in traj.goal)
        m.started = time.monotonic()
        self._active = m
        self.executions.append(
            ExecutionRecord(self.session, m.mid, kind, int(traj.t_s.size), m.started)
        )
        m.task = asyncio.create_task(self._execute(m, traj, self.session))

    async def _execute(self, m: _Move, traj: JointTrajectory, session: str) -> None:
        try:
            report = await self.driver.move(traj)
        except asyncio.CancelledError:
            self._set_outcome(m, "STOPPED", "controller shut down")
            raise
        except Exception as exc:  # the backing driver refused or failed
            status = "ESTOP" if self._estopped() else "FAULT"
            self._set_outcome(m, status, f"{type(exc).__name__}: {exc}")
        else:
            status = {"done": "DONE", "stopped": "STOPPED", "estop": "ESTOP"}.get(
                report.reason, "FAULT"
            )
            reason = report.reason
            if m.watchdog and status == "STOPPED":
                status, reason = "WATCHDOG", f"host silent for {self.watchdog_s:g} s"
            self._set_outcome(m, status, reason, duration_s=report.duration_s, q=report.final_q)
        finally:
            if self._active is m:
                self._active = None
        assert m.outcome is not None
        self._on_done(session, m.outcome)

    def _set_outcome(
        self,
        m: _Move,
        status: str,
        reason: str,
        *,
        duration_s: float | None = None,
        q: tuple[float, ...] | None = None,
    ) -> None:
        q = q if q is not None else tuple(self.driver.state.q)
        err = float(np.abs(np.subtract(q, m.goal)).max()) if m.goal else 0.0
        if duration_s is None:
            duration_s = time.monotonic() - m.started if m.started else 0.0
        m.status = status
        m.outcome = MoveOutcome(m.mid, status, duration_s, tuple(q), err, reason)

    def _outcome(self, m: _Move) -> MoveOutcome:
        if m.outcome is not None:
            return m.outcome
        q = tuple(self.driver.state.q)
        err = float(np.abs(np.subtract(q, m.goal)).max()) if m.goal else 0.0
        dur = time.monotonic() - m.started if m.started else 0.0
        return MoveOutcome(m.mid, m.status, dur, q, err, "")

    def _remember(self, m: _Move) -> None:
        self._moves[m.mid] = m
        self._last_mid = m.mid
        if len(self._moves) > _MAX_MOVES:  # forget the oldest finished moves
            for mid in [
                k for k, v in self._moves.items() if v.status not in ("LOADING", "RUNNING")
            ]:
                del self._moves[mid]
                if len(self._moves) <= _MAX_MOVES // 2:
                    break
