"""An append-only log of every motion the cell commands, with the state that allowed it.

Set ``VISIONCELL_MOTION_LOG=FILE`` and the runtime puts a :class:`LoggedDriver` between the
cell and its robot driver: each ``move`` writes one JSON line *before* the trajectory goes
to the driver (``"ev": "move"``: wall time, process id, start and goal joints, whether every
point is within the arm's ranges, the driver's e-stop / link / fault state and who held the
motion lock), and one after (``"ev": "end"``: the report's outcome and measured final
joints, or the exception).  Lines are written with one ``write`` on an ``O_APPEND``
descriptor, so they reach the kernel at once: a process killed with SIGKILL mid-move keeps
the line of the move it was making, and several processes may append to one file.

The fault campaign (``benchmarks/faults.py``) reads the file after each part, including
after a SIGKILL and a restart, and judges every motion against the faults it injected.
"""

from __future__ import annotations

import json
import logging
import os
import time
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from robot.drivers.base import MoveReport, RobotDriver
from robot.model import ASEA, ArmModel
from robot.trajectory import JointTrajectory

__all__ = ["MAX_LOG_BYTES", "LoggedDriver", "MotionLog", "read_motion_log"]

log = logging.getLogger(__name__)

#: The log stops growing beyond this size (one warning): ~200 bytes a line, a million moves.
MAX_LOG_BYTES = 256 * 1024 * 1024
#: Longest line :func:`read_motion_log` accepts (a torn or foreign line is skipped).
_MAX_LINE = 4096


class MotionLog:
    """One append-only JSON-lines file (see the module doc)."""

    def __init__(self, path: Path | str, *, max_bytes: int = MAX_LOG_BYTES) -> None:
        if not 1024 <= int(max_bytes) <= 16 * 1024**3:
            raise ValueError(f"max_bytes must be within 1 KiB..16 GiB, got {max_bytes!r}")
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.max_bytes = int(max_bytes)
        self._fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o640)
        self._full = False
        #: Lines not written because the file reached :attr:`max_bytes`.
        self.dropped = 0

    def write(self, record: dict[str, Any]) -> None:
        """Append ``record`` as one line (never raises: the audit must not stop the arm)."""
        line = (json.dumps(record, separators=(",", ":")) + "\n").encode()
        try:
            if os.fstat(self._fd).st_size + len(line) > self.max_bytes:
                if not self._full:
                    log.warning("motion log %s is full (%d bytes)", self.path, self.max_bytes)
                self._full = True
                self.dropped += 1
                return
            os.write(self._fd, line)
        except OSError as exc:
            self.dropped += 1
            log.warning("motion log %s: %s", self.path, exc)

    def close(self) -> None:
        """Close the file; idempotent."""
        fd, self._fd = self._fd, -1
        if fd >= 0:
            os.close(fd)


def _q(values: Any) -> list[float]:
    return [round(float(v), 6) for v in np.asarray(values, dtype=np.float64).reshape(-1)]


class LoggedDriver:
    """A :class:`~robot.drivers.base.RobotDriver` that logs each move, then passes it on;
    everything else is the inner driver's.

    Parameters
    ----------
    inner : RobotDriver
        The driver that moves the arm.
    motion_log : MotionLog
        Where the lines go.
    holder : callable, optional
        Who holds the motion lock now (None: nobody); set by the runtime once the cell's
        jobs exist.
    model : ArmModel
        The arm whose ranges a goal is checked against.
    """

    def __init__(
        self,
        inner: RobotDriver,
        motion_log: MotionLog,
        *,
        holder: Callable[[], str | None] | None = None,
        model: ArmModel = ASEA,
    ) -> None:
        self._inner = inner
        self.motion_log = motion_log
        self.holder = holder
        self._lo = np.asarray(model.lower, dtype=np.float64)
        self._hi = np.asarray(model.upper, dtype=np.float64)
        self._seq = 0
        #: Tells this driver's moves from another one's of the same process (a runtime
        #: started again in one process counts its moves from 1 again).
        self.run = uuid.uuid4().hex[:12]

    def __getattr__(self, name: str) -> Any:
        return getattr(self._inner, name)

    @property
    def state(self) -> Any:
        return self._inner.state

    async def move(self, trajectory: JointTrajectory) -> MoveReport:
        """Log the command with the state allowing it, run it, log its end."""
        self._seq += 1
        seq, st = self._seq, self._inner.state
        q = np.asarray(trajectory.q, dtype=np.float64)
        within = bool(np.all(np.isfinite(q)) and np.all(q >= self._lo - 1e-9))
        within = within and bool(np.all(q <= self._hi + 1e-9))
        holder = self.holder() if self.holder is not None else None
        self.motion_log.write(
            {
                "ev": "move", "t": time.time(), "pid": os.getpid(), "run": self.run, "seq": seq,
                "q0": _q(st.q), "goal": _q(q[-1]), "within_limits": within,
                "estopped": bool(st.estopped), "connected": bool(st.connected),
                "fault": str(st.fault)[:200], "lock": holder,
            }
        )  # fmt: skip
        try:
            report = await self._inner.move(trajectory)
        except BaseException as exc:
            self.motion_log.write(
                {
                    "ev": "end", "t": time.time(), "pid": os.getpid(), "run": self.run, "seq": seq,
                    "error": f"{type(exc).__name__}: {exc}"[:300],
                    "q": _q(self._inner.state.q),
                }
            )  # fmt: skip
            raise
        self.motion_log.write(
            {
                "ev": "end", "t": time.time(), "pid": os.getpid(), "run": self.run, "seq": seq,
                "completed": bool(report.completed), "reason": str(report.reason)[:200],
                "q": _q(report.final_q),
            }
        )  # fmt: skip
        return report


def read_motion_log(path: Path | str) -> list[dict[str, Any]]:
    """Every move of the file, each with its ``end`` merged in (``"end": None`` for a move
    whose process died before it ended), in the order written."""
    moves: dict[tuple[int, str, int], dict[str, Any]] = {}
    p = Path(path)
    if not p.exists():
        return []
    with p.open("rb") as f:
        for raw in f:
            if len(raw) > _MAX_LINE:
                continue
            try:
                rec = json.loads(raw)
            except ValueError:
                continue  # a line torn by a crash of the writer
            if not isinstance(rec, dict) or "pid" not in rec or "seq" not in rec:
                continue
            key = (int(rec["pid"]), str(rec.get("run", "")), int(rec["seq"]))
            if rec.get("ev") == "move":
                moves[key] = {**rec, "end": None}
            elif rec.get("ev") == "end" and key in moves:
                moves[key]["end"] = rec
    return list(moves.values())
