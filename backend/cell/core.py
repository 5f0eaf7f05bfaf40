"""The cell: one robot driver, one camera, conveyors, the jobs that use them, one event bus.

REST handlers, the 3D view's buttons, the CLI and jobs all call these methods, so that an
E-STOP pressed anywhere takes the same path: the arm halts first, then every conveyor, then
motion jobs are cancelled; everything stays stopped until :meth:`Cell.reset`.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from backend.cell.camera import CameraFeed
from backend.cell.events import ArmState, CameraStatus, CellStopped, EventBus
from backend.cell.motion import CellMotion, Pose, _report_dict
from backend.cell.viewlog import CalibrationViewLog
from backend.jobs import Job, JobManager
from backend.settings import Settings
from robot.collision import CollisionWorld
from robot.drivers.base import RobotDriver, RobotState
from robot.drivers.conveyor import ConveyorDriver
from robot.model import ASEA, ArmModel
from robot.trajectory import JointTrajectory
from vision.sources import Camera, Frame

__all__ = ["Cell"]

log = logging.getLogger(__name__)

#: Largest rate of :class:`ArmState` events, Hz (changes of the flags go out at once).
ARM_EVENT_HZ = 20.0


class Cell(CellMotion):
    """Owns the driver, the camera feed, the conveyors, the jobs and the bus of one cell.

    Parameters
    ----------
    settings : Settings
        Process configuration (``cell_name`` names the cell).
    driver : RobotDriver
        Connected by :meth:`start`.
    camera : Camera
        Acquired by the :class:`~backend.cell.camera.CameraFeed` started in :meth:`start`;
        failures show in :meth:`camera_status`, they do not stop the cell.
    model : ArmModel
        The arm (joint ranges, named configurations).
    world : CollisionWorld, optional
        Obstacles every move is checked against (None: no check).
    conveyors : sequence of ConveyorDriver
        Halted by :meth:`estop`, resumed by :meth:`reset`.
    bus : EventBus, optional
        The cell's event bus (a new one by default).
    """

    def __init__(
        self,
        settings: Settings,
        driver: RobotDriver,
        camera: Camera,
        *,
        model: ArmModel = ASEA,
        world: CollisionWorld | None = None,
        conveyors: Sequence[ConveyorDriver] = (),
        bus: EventBus | None = None,
    ) -> None:
        self.settings = settings
        self.name = settings.cell_name
        self.driver = driver
        self.camera = camera
        self.model = model
        self.world = world
        self.conveyors = list(conveyors)
        self.bus = bus or EventBus()
        self.jobs = JobManager(publish=self.bus.publish)
        self.feed = CameraFeed(
            camera,
            fps=settings.camera_fps,
            idle_fps=settings.camera_idle_fps,
            publish=self.bus.publish,
        )
        self.calibration_views = CalibrationViewLog(self.bus.publish)
        self.speed = 0.5
        self.db_id: int | None = None
        """Id of the cell's database row (set by :class:`~backend.runtime.CellRuntime`)."""
        self._state_task: asyncio.Task[None] | None = None

    # -- life cycle ----------------------------------------------------------------------
    async def start(self) -> None:
        """Connect the driver, start camera acquisition and the arm-state events."""
        await self.driver.connect()
        self.feed.start()
        self._state_task = asyncio.create_task(self._publish_states(), name="arm-state-events")

    async def stop(self) -> None:
        """Cancel jobs, stop the events and acquisition, close camera and driver."""
        await self.jobs.shutdown()
        if self._state_task is not None:
            self._state_task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._state_task
            self._state_task = None
        await self.feed.stop()
        await self.driver.close()

    async def _publish_states(self) -> None:
        """Arm states onto the bus at <= :data:`ARM_EVENT_HZ`, flag changes at once."""
        last_t = 0.0
        last_flags: tuple[bool, bool, str] | None = None
        while True:
            try:
                async for state in self.driver.states():
                    flags = (state.connected, state.estopped, state.fault)
                    now = time.monotonic()
                    if flags == last_flags and now - last_t < 1.0 / ARM_EVENT_HZ:
                        continue
                    last_t, last_flags = now, flags
                    self.bus.publish(ArmState(state=state, speed=self.speed))
            except asyncio.CancelledError:
                raise
            except Exception:  # a driver's stream failing must not end the events for good
                log.exception("arm state stream of %s failed; restarting", self.driver.name)
            await asyncio.sleep(0.5)  # the stream ended or failed: follow it again shortly

    # -- motion jobs (the REST API's moves) ----------------------------------------------------
    def _start_motion(self, kind: str, traj: JointTrajectory, params: dict[str, Any]) -> Job:
        """Run the planned ``traj`` as a motion job (refused if the arm is taken)."""
        self.check_can_move()

        async def body(job: Job) -> dict[str, Any]:
            job.report(0.0, f"moving for {traj.duration_s:.2f} s")
            self.check_commandable()
            report = await self.driver.move(traj)
            job.report(1.0, report.reason)
            return _report_dict(report)

        return self.jobs.start(kind, body, motion=True, params=params)

    def move_joints(self, q: ArrayLike, *, speed: float | None = None, kind: str = "move") -> Job:
        """Start a joint move job to ``q`` (radians); limits and collisions are checked
        before anything moves."""
        self.check_can_move()
        traj = self.plan_move(q, speed=speed)
        s = self.speed if speed is None else float(speed)
        return self._start_motion(kind, traj, {"joints": traj.goal.tolist(), "speed": s})

    def move_pose(
        self, pose: ArrayLike, *, roll: float = 0.0, speed: float | None = None, path: str = "joint"
    ) -> Job:
        """Move the flange to the chapter pose ``(x, y, z, u, w)`` with ``roll`` about the
        approach axis, as a job.

        ``path="joint"`` solves IK (the branch nearest the current configuration) and makes a
        synchronised joint move; ``path="line"`` moves the flange along a straight line, checked
        for limits and branch continuity along the whole path.  Unreachable targets raise
        :class:`~robot.errors.Unreachable` before anything moves.
        """
        if path not in ("joint", "line"):
            raise ValueError(f"path must be 'joint' or 'line', got {path!r}")
        self.check_can_move()
        values = [float(v) for v in np.asarray(pose, dtype=np.float64).ravel()]
        if len(values) != 5:
            raise ValueError(f"pose must be (x, y, z, u, w), got {values}")
        x, y, z, u, w = values
        target = Pose(x, y, z, u, w, roll=roll)
        traj = self.plan_move(target, speed=speed, path=path)  # type: ignore[arg-type]
        s = self.speed if speed is None else float(speed)
        params: dict[str, Any] = {"pose": values, "roll": roll, "speed": s, "path": path}
        if path == "joint":
            params["joints"] = traj.goal.tolist()
        return self._start_motion("move_pose" if path == "joint" else "move_line", traj, params)

    def home(self, *, speed: float | None = None) -> Job:
        """Move to ``q_home``."""
        return self.move_joints(self.model.q_home, speed=speed, kind="home")

    async def stop_motion(self) -> None:
        """Controlled stop of the current move."""
        await self.driver.stop()

    async def estop(self) -> None:
        """Cell-wide emergency stop: the arm halts first, then every conveyor; then motion
        jobs are cancelled.  Latched until :meth:`reset`."""
        halted: list[str] = []
        try:
            await self.driver.estop()
        finally:  # the belts stop even when the arm's driver cannot be reached
            for conveyor in self.conveyors:
                try:
                    await conveyor.halt()
                    halted.append(conveyor.name)
                except Exception:  # one failing conveyor must not keep the others running
                    log.exception("E-STOP: conveyor %s did not halt", conveyor.name)
            for job in self.jobs.running(motion=True):
                await self.jobs.cancel(job)
            self.bus.publish(CellStopped(active=True, conveyors=tuple(halted)))

    async def reset(self) -> None:
        """Clear an emergency stop: the arm first, then the conveyors resume."""
        await self.driver.reset()
        resumed = []
        for conveyor in self.conveyors:
            await conveyor.resume()
            resumed.append(conveyor.name)
        self.bus.publish(CellStopped(active=False, conveyors=tuple(resumed)))

    @property
    def estopped(self) -> bool:
        """True while the arm or any conveyor is held by the emergency stop."""
        return self.driver.state.estopped or any(c.halted for c in self.conveyors)

    # -- camera --------------------------------------------------------------------------
    @property
    def latest_frame(self) -> Frame | None:
        """The newest camera frame (None before the first one); see :class:`CameraFeed`."""
        return self.feed.latest

    def latest_jpeg(self, *, quality: int = 80) -> bytes | None:
        """The newest frame as JPEG, encoded once per frame."""
        return self.feed.latest_jpeg(quality=quality)

    async def latest_jpeg_async(self, *, quality: int = 80) -> bytes | None:
        """:meth:`latest_jpeg` with the encoding in a worker thread (off the event loop);
        a frame encoded already is answered at once."""
        self.feed.note_demand()
        jpeg = self.feed.encoded_jpeg(quality=quality)
        if jpeg is not None:
            return jpeg
        return await asyncio.to_thread(self.feed.latest_jpeg, quality=quality, demand=False)

    def camera_status(self) -> CameraStatus:
        """Name, health, frame count, rate and last error of the camera."""
        return self.feed.status()

    @property
    def state(self) -> RobotState:
        """The arm's latest state."""
        return self.driver.state
