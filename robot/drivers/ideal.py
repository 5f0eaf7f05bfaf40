"""The ideal driver: follows joint trajectories exactly, in time, with no dynamics.

It stands in for an arm when neither the simulator nor a controller is wanted (unit tests,
a quick demo, the serial emulator's default backing).  Time can run faster than the wall
clock with ``time_scale`` so tests do not wait for real seconds.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import AsyncIterator

import numpy as np
from numpy.typing import ArrayLike

from robot.drivers.base import GripReport, MoveReport, RobotState, StateHub, check_grip_flag
from robot.errors import DriverError, RobotBusy
from robot.model import ASEA, ArmModel, check_joints
from robot.trajectory import JointTrajectory

__all__ = ["IdealDriver"]

_START_TOLERANCE_RAD = 1e-3


class IdealDriver:
    """A :class:`~robot.drivers.base.RobotDriver` that tracks trajectories perfectly.

    Parameters
    ----------
    q0 : array_like of shape (5,), optional
        Initial configuration (default ``model.q_home``).
    model : ArmModel
        Joint ranges used by the limit gate.
    rate_hz : float
        State publishing rate, Hz.
    time_scale : float
        Trajectory seconds per wall-clock second (1 = real time, 10 = ten times faster).

    The gripper is book-keeping only: switched on it reports a part held (there is no
    world to say otherwise), switched off it reports the release.
    """

    name = "ideal"

    def __init__(
        self,
        q0: ArrayLike | None = None,
        *,
        model: ArmModel = ASEA,
        rate_hz: float = 50.0,
        time_scale: float = 1.0,
    ) -> None:
        if not rate_hz > 0:
            raise ValueError(f"rate_hz must be positive, got {rate_hz!r}")
        if not time_scale > 0:
            raise ValueError(f"time_scale must be positive, got {time_scale!r}")
        self.model = model
        self.rate_hz = float(rate_hz)
        self.time_scale = float(time_scale)
        q = check_joints(model.q_home if q0 is None else q0, model)
        self._q = np.array(q, dtype=np.float64)
        self._qd = np.zeros(5)
        self._hub = StateHub(RobotState(tuple(self._q), connected=False))
        self._moving = False
        self._estopped = False
        self._halt = asyncio.Event()
        self._halt_reason = ""
        self._publisher: asyncio.Task[None] | None = None
        self._lock = asyncio.Lock()
        self._gripper_on = False

    # -- protocol ---------------------------------------------------------------------
    async def connect(self) -> None:
        if self._publisher is None:
            self._publisher = asyncio.create_task(self._publish_loop(), name="ideal-driver-state")
        self._publish()

    async def close(self) -> None:
        self._request_halt("stopped")
        if self._publisher is not None:
            self._publisher.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._publisher
            self._publisher = None
        self._hub.publish(RobotState(tuple(self._q), connected=False))

    @property
    def state(self) -> RobotState:
        return self._hub.latest

    def states(self) -> AsyncIterator[RobotState]:
        return self._hub.stream()

    async def move(self, trajectory: JointTrajectory) -> MoveReport:
        if self._publisher is None:
            raise DriverError("ideal driver is not connected")
        if self._estopped:
            raise RobotBusy("emergency stop is active: reset before moving")
        check_joints(trajectory.q, self.model)
        if self._lock.locked():  # busy first, as the other drivers: the arm is still moving
            raise RobotBusy("a move is already executing")
        gap = float(np.abs(trajectory.start - self._q).max())
        if gap > _START_TOLERANCE_RAD:
            raise DriverError(
                f"trajectory starts {gap:.4g} rad away from the current configuration "
                f"(tolerance {_START_TOLERANCE_RAD} rad)"
            )
        async with self._lock:
            self._halt.clear()
            self._halt_reason = ""
            self._moving = True
            t0 = time.monotonic()
            reason = "done"
            try:
                while True:
                    t = (time.monotonic() - t0) * self.time_scale
                    q, qd = trajectory.sample(t)
                    self._q, self._qd = q, qd
                    self._publish()
                    if t >= trajectory.duration_s:
                        break
                    with contextlib.suppress(TimeoutError):
                        async with asyncio.timeout(1.0 / self.rate_hz):
                            await self._halt.wait()
                    if self._halt.is_set():
                        reason = self._halt_reason or "stopped"
                        break
            except asyncio.CancelledError:
                reason = "cancelled"
                raise
            finally:
                self._qd = np.zeros(5)
                self._moving = False
                self._publish()
            elapsed = min((time.monotonic() - t0) * self.time_scale, trajectory.duration_s)
            err = float(np.abs(self._q - trajectory.goal).max())
            return MoveReport(
                completed=reason == "done",
                reason=reason,
                duration_s=elapsed,
                final_q=tuple(float(v) for v in self._q),
                final_error_rad=err,
            )

    async def stop(self) -> None:
        self._request_halt("stopped")

    async def estop(self) -> None:
        self._estopped = True
        self._request_halt("estop")
        self._publish()

    async def reset(self) -> None:
        self._estopped = False
        self._publish()

    async def grip(self, on: bool) -> GripReport:
        on = check_grip_flag(on)
        if self._publisher is None:
            raise DriverError("ideal driver is not connected")
        if self._estopped:
            raise RobotBusy("emergency stop is active: reset before using the gripper")
        was = self._gripper_on
        self._gripper_on = on
        self._publish()
        if on:
            return GripReport(True, True, detail="suction on")
        return GripReport(False, False, detail="released" if was else "suction already off")

    # -- internals --------------------------------------------------------------------
    def _request_halt(self, reason: str) -> None:
        if self._moving:
            self._halt_reason = reason
            self._halt.set()

    def _publish(self) -> None:
        self._hub.publish(
            RobotState(
                q=tuple(float(v) for v in self._q),
                qd=tuple(float(v) for v in self._qd),
                connected=self._publisher is not None,
                moving=self._moving,
                estopped=self._estopped,
                gripper_on=self._gripper_on,
                holding=self._gripper_on,
            )
        )

    async def _publish_loop(self) -> None:
        period = 1.0 / self.rate_hz
        while True:
            await asyncio.sleep(period)
            if not self._moving:
                self._publish()
