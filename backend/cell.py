"""The cell: one robot driver, one camera, the jobs that use them, and their shared state.

REST handlers, the 3D view's buttons and the console all call these methods, so that an
E-STOP pressed anywhere takes the same path.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from numpy.typing import ArrayLike

from backend.jobs import Job, JobManager
from backend.settings import Settings
from robot.drivers.base import MoveReport, RobotDriver
from robot.errors import RobotBusy
from robot.kinematics import ik
from robot.model import ASEA, ArmModel, check_joints
from robot.trajectory import MIN_SPEED, JointTrajectory, plan_joint_move
from robot.trajectory_cartesian import plan_cartesian_line
from vision.errors import CameraError, InvalidInput
from vision.sources import Camera, Frame

__all__ = ["CameraStatus", "Cell"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class CameraStatus:
    """What the console shows about the image source."""

    name: str
    ok: bool
    frames: int
    fps: float
    error: str


class Cell:
    """Owns the driver, the camera task and the jobs of one robot cell.

    Parameters
    ----------
    settings : Settings
        Process configuration.
    driver : RobotDriver
        Connected by :meth:`start`.
    camera : Camera
        Opened by :meth:`start`; failures are reported in :meth:`camera_status`, they do not
        stop the cell.
    model : ArmModel
        The arm (joint ranges, named configurations).
    """

    def __init__(
        self, settings: Settings, driver: RobotDriver, camera: Camera, *, model: ArmModel = ASEA
    ) -> None:
        self.settings = settings
        self.driver = driver
        self.camera = camera
        self.model = model
        self.jobs = JobManager()
        self.speed = 0.5
        self._frame: Frame | None = None
        self._jpeg: tuple[int, bytes] | None = None
        self._frames = 0
        self._fps = 0.0
        self._dt = 0.0
        self._camera_error = ""
        self._camera_task: asyncio.Task[None] | None = None
        # Frames are acquired at camera_fps while someone reads them, else at camera_idle_fps.
        self._demand_until = 0.0
        self._wake = asyncio.Event()

    # -- life cycle ----------------------------------------------------------------------
    async def start(self) -> None:
        """Connect the driver and start camera acquisition."""
        await self.driver.connect()
        self._camera_task = asyncio.create_task(self._acquire(), name="camera-acquisition")

    async def stop(self) -> None:
        """Cancel jobs, stop acquisition, close camera and driver (in that order)."""
        await self.jobs.shutdown()
        if self._camera_task is not None:
            self._camera_task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._camera_task
        with contextlib.suppress(Exception):
            await self.camera.close()
        await self.driver.close()

    # -- motion --------------------------------------------------------------------------
    def _check_speed(self, speed: float | None) -> float:
        s = self.speed if speed is None else speed
        if isinstance(s, bool) or not (MIN_SPEED <= s <= 1.0):
            raise InvalidInput(f"speed must be in [{MIN_SPEED}, 1], got {s!r}")
        return float(s)

    def check_can_move(self) -> None:
        """Raise :class:`RobotBusy` if a motion would be refused now: the emergency stop is
        latched, or another job holds the arm. For callers with work to do before their
        motion job starts (planning), so that they refuse before doing it."""
        if self.driver.state.estopped:
            raise RobotBusy("emergency stop is active: reset before moving")
        self.jobs.check_arm_free()

    def _start_motion(self, kind: str, traj: JointTrajectory, params: dict[str, Any]) -> Job:
        """Run ``traj`` as a motion job (the motion lock refuses a second one)."""
        self.check_can_move()

        async def body(job: Job) -> dict[str, Any]:
            job.report(0.0, f"moving for {traj.duration_s:.2f} s")
            report: MoveReport = await self.driver.move(traj)
            job.report(1.0, report.reason)
            return {
                "completed": report.completed,
                "reason": report.reason,
                "duration_s": report.duration_s,
                "final_joints": list(report.final_q),
                "final_error_rad": report.final_error_rad,
                "rms_tracking_error_rad": report.rms_tracking_error_rad,
                "max_tracking_error_rad": report.max_tracking_error_rad,
            }

        return self.jobs.start(kind, body, motion=True, params=params)

    def move_joints(self, q: ArrayLike, *, speed: float | None = None, kind: str = "move") -> Job:
        """Start a joint move job to ``q`` (radians); the limit gate runs before anything moves."""
        goal = check_joints(np.asarray(q, dtype=np.float64).reshape(-1), self.model)
        s = self._check_speed(speed)
        traj = plan_joint_move(self.driver.state.q, goal, speed=s, model=self.model)
        return self._start_motion(kind, traj, {"joints": goal.tolist(), "speed": s})

    def move_pose(
        self, pose: ArrayLike, *, roll: float = 0.0, speed: float | None = None, path: str = "joint"
    ) -> Job:
        """Move the flange to the chapter pose ``(x, y, z, u, w)`` with ``roll`` about the approach axis.

        ``path="joint"`` solves IK (the branch nearest the current configuration) and makes a
        synchronised joint move; ``path="line"`` moves the flange along a straight line, checked
        for limits and branch continuity along the whole path.  Unreachable targets raise
        :class:`~robot.errors.Unreachable` before anything moves.
        """
        s = self._check_speed(speed)
        params = {
            "pose": [float(v) for v in np.asarray(pose, dtype=np.float64).ravel()],
            "roll": roll,
            "speed": s,
            "path": path,
        }
        q_now = np.asarray(self.driver.state.q)
        if path == "joint":
            goal = ik(pose, roll=roll, seed=q_now, model=self.model)
            traj = plan_joint_move(q_now, goal, speed=s, model=self.model)
            return self._start_motion("move_pose", traj, {**params, "joints": goal.tolist()})
        if path == "line":
            traj = plan_cartesian_line(q_now, pose, roll=roll, speed=s, model=self.model)
            return self._start_motion("move_line", traj, params)
        raise ValueError(f"path must be 'joint' or 'line', got {path!r}")

    def home(self, *, speed: float | None = None) -> Job:
        """Move to ``q_home``."""
        return self.move_joints(self.model.q_home, speed=speed, kind="home")

    async def stop_motion(self) -> None:
        """Controlled stop of the current move."""
        await self.driver.stop()

    async def estop(self) -> None:
        """Emergency stop: the driver halts first, then motion jobs are cancelled."""
        await self.driver.estop()
        for job in self.jobs.running(motion=True):
            await self.jobs.cancel(job)

    async def reset(self) -> None:
        """Clear an emergency stop."""
        await self.driver.reset()

    # -- camera --------------------------------------------------------------------------
    def _note_demand(self) -> None:
        """Someone reads frames: acquire at the full rate for the next 2 s."""
        now = time.monotonic()
        if now >= self._demand_until:
            self._wake.set()  # end an idle wait at once
        self._demand_until = now + 2.0

    async def _acquire(self) -> None:
        backoff = 0.5
        opened = False
        t_last = time.monotonic()
        while True:
            try:
                if not opened:
                    await self.camera.open()
                    opened = True
                    self._camera_error = ""
                    backoff = 0.5
                t0 = time.monotonic()
                frame = await self.camera.grab()
                self._frame = frame
                self._frames += 1
                now = time.monotonic()
                dt = now - t_last
                t_last = now
                # Average the interval, not its inverse (an average of 1/dt is biased upward).
                self._dt = dt if self._dt == 0.0 else 0.9 * self._dt + 0.1 * dt
                self._fps = 1.0 / self._dt if self._dt > 0 else 0.0
                busy = time.monotonic() < self._demand_until
                fps = self.settings.camera_fps if busy else self.settings.camera_idle_fps
                self._wake.clear()
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(
                        self._wake.wait(), max(0.0, 1.0 / fps - (time.monotonic() - t0))
                    )
            except asyncio.CancelledError:
                raise
            except (CameraError, OSError) as exc:
                if str(exc) != self._camera_error:
                    log.warning("camera %s: %s", self.camera.name, exc)
                self._camera_error = str(exc)
                opened = False
                with contextlib.suppress(Exception):
                    await self.camera.close()
                await asyncio.sleep(backoff)
                backoff = min(backoff * 2.0, 10.0)

    @property
    def latest_frame(self) -> Frame | None:
        """The newest camera frame (None before the first one).

        Reading it keeps acquisition at ``camera_fps`` for 2 s; unread, the camera task
        slows to ``camera_idle_fps``.
        """
        self._note_demand()
        return self._frame

    def latest_jpeg(self, *, quality: int = 80) -> bytes | None:
        """The newest frame as JPEG, encoded once per frame."""
        self._note_demand()
        frame = self._frame
        if frame is None:
            return None
        if self._jpeg is None or self._jpeg[0] != id(frame):
            ok, buf = cv2.imencode(
                ".jpg",
                cv2.cvtColor(frame.rgb, cv2.COLOR_RGB2BGR),
                [cv2.IMWRITE_JPEG_QUALITY, quality],
            )
            if not ok:
                return None
            self._jpeg = (id(frame), buf.tobytes())
        return self._jpeg[1]

    def camera_status(self) -> CameraStatus:
        """Name, health, frame count and rate of the camera."""
        return CameraStatus(
            name=self.camera.name,
            ok=self._frame is not None and not self._camera_error,
            frames=self._frames,
            fps=round(self._fps, 2),
            error=self._camera_error,
        )
