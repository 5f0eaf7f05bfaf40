"""The simulated arm and camera behind the product's protocols.

:class:`SimDriver` implements :class:`robot.drivers.base.RobotDriver` on a
:class:`~robot.sim.engine.SimEngine` (torque-controlled MuJoCo arm), and :class:`SimCamera`
implements :class:`vision.sources.Camera` with the eye-in-hand camera of the same engine.
Both may share one engine (one per process): the first to open it starts it, the last to
close it stops it.  The engine's threads hand results to the event loop with
``loop.call_soon_threadsafe``.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Callable
from dataclasses import replace

import numpy as np

from robot.drivers.base import GripReport, MoveReport, RobotState, StateHub, check_grip_flag
from robot.errors import DriverError, RobotBusy
from robot.model import check_joints
from robot.sim.camera import CameraSpec
from robot.sim.engine import ArmSample, SimEngine, Snapshot
from robot.sim.imaging import Imager
from robot.trajectory import JointTrajectory
from vision.errors import CameraError
from vision.sources import Frame

__all__ = ["SimCamera", "SimDriver"]

_START_TOLERANCE_RAD = 1e-3


def _state(sample: ArmSample | Snapshot, *, connected: bool = True) -> RobotState:
    return RobotState(
        q=tuple(float(v) for v in sample.q),
        qd=tuple(float(v) for v in sample.qd),
        stamp_s=sample.stamp_s,
        connected=connected,
        moving=sample.moving,
        estopped=sample.estopped,
        gripper_on=sample.gripper_on,
        holding=sample.holding,
    )


class SimDriver:
    """A :class:`~robot.drivers.base.RobotDriver` for the simulated, torque-driven arm.

    Parameters
    ----------
    engine : SimEngine
        The simulation (shared with :class:`SimCamera`).
    time_scale : float, optional
        Sets the engine's simulated seconds per wall-clock second (tests run faster than
        real time); None keeps the engine's.

    Moves are tracked by the engine's joint controller; :meth:`move` returns the
    :class:`~robot.drivers.base.MoveReport` with the RMS and largest tracking error over the
    trajectory and the final error after settling.  :meth:`estop` holds the arm where it is
    at once and refuses moves (:class:`~robot.errors.RobotBusy`) until :meth:`reset`.
    """

    name = "sim"

    def __init__(self, engine: SimEngine, *, time_scale: float | None = None) -> None:
        self.engine = engine
        self.model = engine.arm_model
        if time_scale is not None:
            engine.time_scale = time_scale
        self._hub = StateHub(_state(engine.arm_state(), connected=False))
        self._loop: asyncio.AbstractEventLoop | None = None
        self._connected = False
        self._busy = False

    # -- protocol ----------------------------------------------------------------------
    async def connect(self) -> None:
        if self._connected:
            return
        self._loop = asyncio.get_running_loop()
        self.engine.add_listener(self._on_sample)
        self.engine.acquire()
        self._connected = True
        self._publish()

    async def close(self) -> None:
        if not self._connected:
            return
        self.engine.stop_motion("stopped")
        self.engine.remove_listener(self._on_sample)
        self._connected = False
        self.engine.release()
        self._hub.publish(_state(self.engine.arm_state(), connected=False))

    @property
    def state(self) -> RobotState:
        return self._hub.latest

    def states(self) -> AsyncIterator[RobotState]:
        return self._hub.stream()

    async def move(self, trajectory: JointTrajectory) -> MoveReport:
        if not self._connected or self._loop is None:
            raise DriverError("sim driver is not connected")
        if self.engine.estopped:
            raise RobotBusy("emergency stop is active: reset before moving")
        check_joints(trajectory.q, self.model)
        if self._busy:
            raise RobotBusy("a move is already executing")
        if self.engine.controller.moving:
            # A cancelled or stopped move still braking: busy, whatever its start point (a
            # retry planned before the cancel would otherwise be refused for its start point).
            raise RobotBusy("the previous move is still executing or stopping")
        q_now = self.engine.arm_state().q
        gap = float(np.abs(trajectory.start - q_now).max())
        if gap > _START_TOLERANCE_RAD:
            raise DriverError(
                f"trajectory starts {gap:.4g} rad away from the current configuration "
                f"(tolerance {_START_TOLERANCE_RAD} rad)"
            )
        loop = self._loop
        done: asyncio.Future[MoveReport] = loop.create_future()

        def on_done(report: MoveReport) -> None:  # physics thread
            loop.call_soon_threadsafe(_resolve, done, report)

        self._busy = True
        try:
            try:
                self.engine.start_move(trajectory, on_done)
            except DriverError as exc:
                raise RobotBusy(str(exc)) from None
            self._publish()
            try:
                return await done
            except asyncio.CancelledError:
                # The caller gave up: the arm decelerates to rest; a new move is refused
                # (RobotBusy) until it has settled.
                self.engine.stop_motion("cancelled")
                raise
        finally:
            self._busy = False
            self._publish()

    async def stop(self) -> None:
        self.engine.stop_motion("stopped")

    async def estop(self) -> None:
        self.engine.brake()
        self._publish()

    async def reset(self) -> None:
        self.engine.clear_estop()
        self._publish()

    async def grip(self, on: bool) -> GripReport:
        """Suction on (the cup seals on the part under it, or on the next one it touches)
        or off (the part drops: into a bin, back onto the belt or onto the floor)."""
        on = check_grip_flag(on)
        if not self._connected:
            raise DriverError("sim driver is not connected")
        if self.engine.estopped:
            raise RobotBusy("emergency stop is active: reset before using the gripper")
        try:
            report = self.engine.grip(on)
        except DriverError as exc:
            raise RobotBusy(str(exc)) from None
        self._publish()
        return report

    # -- internals ---------------------------------------------------------------------
    def _publish(self) -> None:
        self._publish_sample(self.engine.arm_state())

    def _publish_sample(self, sample: ArmSample) -> None:  # event loop
        # A physics-thread sample queued before a reset or e-stop may arrive after the state
        # published by that call: publishing it would bring the old flags back until the next
        # sample, so anything older than what was published last is dropped.
        latest = self._hub.latest
        if latest is not None and sample.stamp_s < latest.stamp_s:
            return
        self._hub.publish(_state(sample, connected=self._connected))

    def _on_sample(self, sample: ArmSample) -> None:  # physics thread
        loop = self._loop
        if loop is not None and not loop.is_closed():
            with contextlib.suppress(RuntimeError):  # the loop closed meanwhile
                loop.call_soon_threadsafe(self._publish_sample, sample)


def _resolve(fut: asyncio.Future[MoveReport], report: MoveReport) -> None:
    if not fut.done():
        fut.set_result(report)


class SimCamera:
    """A :class:`vision.sources.Camera`: the eye-in-hand camera of a :class:`SimEngine`.

    ``grab()`` takes a snapshot of the cell (the moment of exposure), renders it on the
    engine's render thread and returns a :class:`~vision.sources.Frame` whose
    ``robot_state`` is the arm's state at that moment and whose ``stamp_s`` is its
    ``time.monotonic()``.

    Parameters
    ----------
    engine : SimEngine
        The simulation (shared with :class:`SimDriver`).
    arm_state : callable, optional
        Where the arm is when the engine does not drive it (e.g. the serial driver with its
        emulator): a function returning the current :class:`RobotState`, whose joints are
        then drawn instead of the engine's.
    """

    name = "sim"

    def __init__(
        self, engine: SimEngine, *, arm_state: Callable[[], RobotState] | None = None
    ) -> None:
        self.engine = engine
        self._arm_state = arm_state
        self._imager: Imager | None = None
        self._open = False
        self._count = 0

    @property
    def spec(self) -> CameraSpec:
        """Current camera settings (geometry fixed; sensor adjustable with :meth:`configure`)."""
        return self._imager.spec if self._imager is not None else self.engine.config.camera

    def configure(
        self,
        *,
        exposure_s: float | None = None,
        gain: float | None = None,
        noise_std_dn: float | None = None,
        motion_blur: bool | None = None,
    ) -> CameraSpec:
        """Change exposure time, gain, noise or motion blur for the next frames."""
        changes = {
            k: v
            for k, v in (
                ("exposure_s", exposure_s),
                ("gain", gain),
                ("noise_std_dn", noise_std_dn),
                ("motion_blur", motion_blur),
            )
            if v is not None
        }
        spec = self.spec.with_(**changes)
        if self._imager is None:
            self._imager = Imager(spec, model=self.engine.arm_model)
        else:
            self._imager.set_sensor(spec)
        return spec

    async def open(self) -> None:
        if self._open:
            return
        self.engine.acquire()
        try:
            if self._imager is None:
                self._imager = await asyncio.to_thread(
                    Imager, self.engine.config.camera, model=self.engine.arm_model
                )
            await asyncio.to_thread(self.engine.renderer)
        except Exception as exc:
            self.engine.release()
            raise CameraError(f"cannot start the simulated camera: {exc}") from exc
        self._open = True

    async def close(self) -> None:
        if self._open:
            self._open = False
            self.engine.release()

    async def grab(self) -> Frame:
        if not self._open or self._imager is None:
            raise CameraError("simulated camera is not open")
        snap = self.engine.snapshot()
        state = _state(snap)
        if self._arm_state is not None:
            ext = self._arm_state()
            snap = _with_joints(snap, ext)
            state = ext
        imager = self._imager
        try:
            image = await asyncio.wrap_future(
                self.engine.renderer().submit(lambda w: imager.render(w, snap))
            )
        except RuntimeError as exc:
            raise CameraError(f"simulated camera failed: {exc}") from exc
        frame = Frame(
            rgb=image.rgb,
            stamp_s=snap.stamp_s,
            index=self._count,
            robot_state=state,
            meta={
                "source": "sim",
                "sim_time_s": snap.t_s,
                "belt_travel_m": snap.belt_travel_m,
                "exposure_s": imager.spec.exposure_s,
                "gain": imager.spec.gain,
            },
        )
        self._count += 1
        return frame


def _with_joints(snap: Snapshot, state: RobotState) -> Snapshot:
    return replace(
        snap,
        q=np.asarray(state.q, dtype=np.float64),
        qd=np.asarray(state.qd, dtype=np.float64),
        moving=state.moving,
        estopped=state.estopped,
    )
