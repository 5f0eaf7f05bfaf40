"""The ``RobotDriver`` protocol and the pieces every driver shares.

A driver owns the link to one arm (simulated, emulated over a serial line, or real).  The
backend talks to it only through :class:`RobotDriver`, so the same cell code drives the
simulator, the serial controller or the ideal follower.  All methods are coroutines run on
the application's event loop; a driver with its own thread (the simulator) hands results
back with ``loop.call_soon_threadsafe``.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from robot.trajectory import JointTrajectory

__all__ = [
    "GripReport",
    "MoveReport",
    "RobotDriver",
    "RobotState",
    "StateHub",
    "check_grip_flag",
]


@dataclass(frozen=True)
class RobotState:
    """One sample of the arm's state.

    Attributes
    ----------
    q : tuple of 5 floats
        Measured joint positions, radians.
    qd : tuple of 5 floats
        Measured joint velocities, rad/s.
    stamp_s : float
        ``time.monotonic()`` of the sample on this host.
    connected : bool
        False while the driver has no link to the arm (the values are the last known).
    moving : bool
        True while a move is being executed.
    estopped : bool
        True after an emergency stop until :meth:`RobotDriver.reset`.
    fault : str
        Empty when healthy, else a short description shown to the operator.
    gripper_on : bool
        True while the suction gripper is commanded on.
    holding : bool
        True while the gripper reports a part held (vacuum established).
    """

    q: tuple[float, ...]
    qd: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0)
    stamp_s: float = field(default_factory=time.monotonic)
    connected: bool = True
    moving: bool = False
    estopped: bool = False
    fault: str = ""
    gripper_on: bool = False
    holding: bool = False

    @property
    def q_array(self) -> NDArray[np.float64]:
        """Joint positions as a float64 array of shape (5,)."""
        return np.asarray(self.q, dtype=np.float64)

    def as_dict(self) -> dict[str, object]:
        """JSON-friendly form used by the API and the console."""
        return {
            "q": list(self.q),
            "qd": list(self.qd),
            "stamp_s": self.stamp_s,
            "connected": self.connected,
            "moving": self.moving,
            "estopped": self.estopped,
            "fault": self.fault,
            "gripper_on": self.gripper_on,
            "holding": self.holding,
        }


@dataclass(frozen=True)
class MoveReport:
    """What happened to one commanded trajectory.

    Attributes
    ----------
    completed : bool
        True if the arm reached the trajectory's end.
    reason : str
        ``"done"``, ``"stopped"``, ``"estop"``, ``"cancelled"`` or a fault description.
    duration_s : float
        Time the move took in the driver's clock (simulated seconds for the simulator).
    final_q : tuple of 5 floats
        Measured joints at the end, radians.
    final_error_rad : float
        Largest absolute joint error to the trajectory's goal at the end.
    rms_tracking_error_rad : float
        RMS over the move of the joint error to the reference (0 for the ideal driver).
    max_tracking_error_rad : float
        Largest joint error to the reference during the move.
    """

    completed: bool
    reason: str
    duration_s: float
    final_q: tuple[float, ...]
    final_error_rad: float = 0.0
    rms_tracking_error_rad: float = 0.0
    max_tracking_error_rad: float = 0.0


@dataclass(frozen=True)
class GripReport:
    """What a gripper command did.

    Attributes
    ----------
    on : bool
        The suction state now (True: on).
    holding : bool
        True if a part is held after the command (vacuum established; always False after
        switching off).
    part_id : int or None
        Which part is held, where the driver can tell (the simulator's object id), else None.
    released_id : int or None
        Switching off: the part that was let go, where the driver can tell.
    detail : str
        Short human-readable outcome (``"no part under the cup"``, ``"released"``...).
    """

    on: bool
    holding: bool
    part_id: int | None = None
    released_id: int | None = None
    detail: str = ""

    def as_dict(self) -> dict[str, object]:
        """JSON-friendly form."""
        return {
            "on": self.on,
            "holding": self.holding,
            "part_id": self.part_id,
            "released_id": self.released_id,
            "detail": self.detail,
        }


def check_grip_flag(on: object) -> bool:
    """The gripper command's argument: a real ``bool`` (numbers and strings are refused)."""
    if not isinstance(on, bool):
        raise ValueError(f"grip(on) takes True or False, got {on!r}")
    return on


@runtime_checkable
class RobotDriver(Protocol):
    """What the backend needs from an arm.

    Every motion command passes the joint-limit gate :func:`robot.model.check_joints`
    before anything moves.
    """

    name: str

    async def connect(self) -> None:
        """Open the link and start publishing states."""

    async def close(self) -> None:
        """Stop publishing and release the link; idempotent."""

    @property
    def state(self) -> RobotState:
        """The latest state (never blocks)."""

    def states(self) -> AsyncIterator[RobotState]:
        """Async iterator over states: the latest first, then each new one (old ones dropped)."""

    async def move(self, trajectory: JointTrajectory) -> MoveReport:
        """Execute ``trajectory`` (which must start near the current state) and await its end."""

    async def stop(self) -> None:
        """Controlled stop: end the current move, the arm holds where it is."""

    async def estop(self) -> None:
        """Emergency stop: halt at once, refuse motion until :meth:`reset`."""

    async def reset(self) -> None:
        """Clear an emergency stop or a fault."""

    async def grip(self, on: bool) -> GripReport:
        """Switch the suction gripper on (pick what is under the cup) or off (release)."""


class StateHub:
    """Latest-value broadcast of :class:`RobotState` to any number of async readers.

    Readers never build a backlog: each holds a one-slot queue that keeps only the newest
    state.  ``publish`` must be called on the event loop's thread.
    """

    def __init__(self, initial: RobotState) -> None:
        self._latest = initial
        self._queues: set[asyncio.Queue[RobotState]] = set()

    @property
    def latest(self) -> RobotState:
        """The most recently published state."""
        return self._latest

    def publish(self, state: RobotState) -> None:
        """Make ``state`` the latest and wake every reader."""
        self._latest = state
        for q in self._queues:
            if q.full():
                q.get_nowait()
            q.put_nowait(state)

    async def stream(self) -> AsyncIterator[RobotState]:
        """Yield the latest state, then every newer one as it arrives."""
        q: asyncio.Queue[RobotState] = asyncio.Queue(maxsize=1)
        self._queues.add(q)
        try:
            yield self._latest
            while True:
                yield await q.get()
        finally:
            self._queues.discard(q)
