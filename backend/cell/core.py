"""The cell: one robot driver, one camera, conveyors, the jobs that use them, one event bus.

REST handlers, the console's WebSocket, the 3D view's buttons, the CLI and jobs all call
these methods, so that an E-STOP pressed anywhere takes the same path: the arm's stop goes
out first and every conveyor's with it, motion jobs are told to cancel, the cell-wide event
goes out, and the caller has its answer; the jobs wind down afterwards.  Everything stays
stopped until :meth:`Cell.reset`.
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
from robot.errors import DriverError
from robot.model import ASEA, ArmModel
from robot.trajectory import JointTrajectory
from vision.sources import Camera, Frame

__all__ = ["Cell"]

log = logging.getLogger(__name__)

#: Largest rate of :class:`ArmState` events, Hz (changes of the flags go out at once).
ARM_EVENT_HZ = 20.0
#: Longest an E-STOP's answer waits for the arm and the conveyors to confirm, seconds (a
#: confirmation later than this is logged; the serial driver's own limit is 0.5 s).
LATCH_WAIT_S = 1.0


def _report_late(what: str) -> Any:
    """A done callback logging the outcome of an E-STOP step that outlived the answer."""

    def done(task: asyncio.Future[Any]) -> None:
        if task.cancelled():
            log.error("E-STOP: %s was cancelled", what)
        elif task.exception() is not None:
            log.error("E-STOP: %s failed late: %r", what, task.exception())
        else:
            log.warning("E-STOP: %s confirmed late", what)

    return done


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
        #: What an E-STOP left running (the cancelled jobs winding down); ended by :meth:`stop`.
        self._background: set[asyncio.Future[None]] = set()

    # -- life cycle ----------------------------------------------------------------------
    async def start(self) -> None:
        """Connect the driver, start camera acquisition and the arm-state events."""
        await self.driver.connect()
        self.feed.start()
        self._state_task = asyncio.create_task(self._publish_states(), name="arm-state-events")

    async def stop(self) -> None:
        """Cancel jobs, stop the events and acquisition, close camera and driver."""
        await self.jobs.shutdown()
        for task in list(self._background):
            task.cancel()
        self._background.clear()
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

    async def estop(
        self, *, by: str = "system", role: str = "system", source: str = "cell"
    ) -> None:
        """Cell-wide emergency stop, latched until :meth:`reset`.

        The arm's stop is sent first and every conveyor's at once after it (a slow
        acknowledgement of the arm does not hold the belts), and the running motion jobs are
        told to cancel (they wake after the stops); the answer waits for the arm and the
        conveyors at most :data:`LATCH_WAIT_S`.  Then the :class:`CellStopped` event goes out (its listeners record the stop: the runtime's
        audit writer) and this returns.  Nothing here waits for the database or for a job
        to end: the jobs wind down (an inspection storing its failed row, perhaps through
        a database outage) in the background.

        ``by``, ``role`` and ``source`` say who pressed it and where (``rest``, ``ws``,
        ``view3d``, ``cli``, ...), for the event and the audit record.  Raises the arm
        driver's error (e.g. the serial link is down) after the conveyors have been halted
        and the event published.
        """
        latch = self._hold(asyncio.ensure_future(self._latch(by=by, role=role, source=source)))
        # Shielded: a caller that goes away (a client disconnecting) never interrupts a latch.
        await asyncio.shield(latch)

    async def _latch(self, *, by: str, role: str, source: str) -> None:
        """The work of :meth:`estop` (see there)."""
        arm = asyncio.ensure_future(self.driver.estop())  # scheduled first: runs first
        belts = {asyncio.ensure_future(c.halt()): c.name for c in self.conveyors}
        # The motion jobs are told now and wake after the stops, scheduled first: a job
        # never sees its move end by the stop and goes on to a next step.
        jobs = [j for j in self.jobs.running(motion=True) if j.task is not None]
        for job in jobs:  # awaited in the background
            assert job.task is not None
            job.task.cancel()
        await asyncio.wait([arm, *belts], timeout=LATCH_WAIT_S)
        halted: list[str] = []
        for task, name in belts.items():
            if not task.done():
                log.error("E-STOP: conveyor %s has not confirmed its halt yet", name)
                task.add_done_callback(_report_late(f"conveyor {name} halt"))
            elif task.cancelled() or task.exception() is not None:
                log.error("E-STOP: conveyor %s did not halt: %r", name,
                          None if task.cancelled() else task.exception())  # fmt: skip
            else:
                halted.append(name)
        arm_error: BaseException | None = None
        if not arm.done():
            arm.add_done_callback(_report_late("arm E-STOP"))
            arm_error = DriverError(f"the arm did not confirm its stop within {LATCH_WAIT_S} s")
        elif arm.cancelled():
            arm_error = DriverError("the arm's stop was cancelled")
        else:
            arm_error = arm.exception()
        self.bus.publish(
            CellStopped(
                active=True, conveyors=tuple(halted), by=by, role=role, source=source,
                arm_latched=arm_error is None, jobs=tuple(j.id for j in jobs),
            )
        )  # fmt: skip
        log.warning(
            "E-STOP pressed by %s (%s) via %s: arm %s, conveyors halted: %s, jobs cancelled: %s",
            by, role, source, "latched" if arm_error is None else f"NOT latched ({arm_error!r})",
            ", ".join(halted) or "none", ", ".join(j.id for j in jobs) or "none",
        )  # fmt: skip
        if jobs:
            self._hold(asyncio.ensure_future(self._wind_down(jobs)))
        if arm_error is not None:
            raise arm_error

    def _hold(self, task: asyncio.Future[None]) -> asyncio.Future[None]:
        """Keep a reference to ``task`` until it ends (:meth:`stop` cancels it)."""
        self._background.add(task)
        task.add_done_callback(self._background.discard)
        return task

    async def _wind_down(self, jobs: list[Job]) -> None:
        """Wait for the end of the jobs an E-STOP cancelled (once: a second cancellation
        would interrupt what a job does on its way out, e.g. storing its failed row)."""
        for job in jobs:
            await self.jobs.wait(job)
            log.info("E-STOP: job %s (%s) ended %s", job.id, job.kind, job.state.value)

    async def reset(
        self, *, by: str = "system", role: str = "system", source: str = "cell"
    ) -> None:
        """Clear an emergency stop: the arm first, then the conveyors resume."""
        await self.driver.reset()
        resumed = []
        for conveyor in self.conveyors:
            await conveyor.resume()
            resumed.append(conveyor.name)
        self.bus.publish(
            CellStopped(active=False, conveyors=tuple(resumed), by=by, role=role, source=source)
        )

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
