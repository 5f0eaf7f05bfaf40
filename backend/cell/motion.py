"""The cell's motion building blocks: ``move_to``, ``settle``, ``look``, ``next_frame``.

Calibration, teaching and inspection all move the arm, wait for it to be still and take a
frame exposed after it stopped.  These coroutines do that once, for every caller:

* :meth:`CellMotion.move_to` plans a synchronised joint move (or a straight flange line) to
  joints or to a chapter pose (IK, eq. 20 inverted), checks the whole path against the
  cell's collision model (:mod:`robot.collision`), executes it under the cell's one arm
  reservation and returns the driver's :class:`~robot.drivers.base.MoveReport`; it raises
  :class:`~robot.errors.Unreachable`, :class:`~robot.errors.JointLimitError`,
  :class:`~backend.cell.errors.PathBlocked`, :class:`~robot.errors.RobotBusy` (arm held
  elsewhere, or E-STOP latched) or :class:`~backend.cell.errors.MoveAborted` (stop,
  E-STOP, fault) with nothing else moved.
* :meth:`CellMotion.settle` waits (bounded) until no joint turns faster than
  :data:`STILL_RAD_S`.
* :meth:`CellMotion.look` = move, settle, then :meth:`CellMotion.next_frame` after the
  moment the arm was found still: never a frame exposed during the move.

Inside a job: the job's coroutine calls these directly.  A motion job holds the arm from
:meth:`~backend.jobs.JobManager.start` to its end, and ``move_to`` sees (through
:func:`backend.jobs.current_job`) that the calling job is the holder, so it moves without
taking the reservation again; any other caller (a job without the arm, a script, the 3D
view) gets the reservation for the one move, or :class:`~robot.errors.RobotBusy` at once.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import math
import time
from collections.abc import Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from backend.cell.errors import MoveAborted, NotStill, PathBlocked
from backend.jobs import current_job
from robot.errors import LinkDown, RobotBusy
from robot.kinematics import ik
from robot.model import check_joints
from robot.trajectory import MIN_SPEED, JointTrajectory, plan_joint_move
from robot.trajectory_cartesian import plan_cartesian_line
from vision.errors import CameraError, InvalidInput
from vision.sources import Frame

if TYPE_CHECKING:
    from backend.cell.camera import CameraFeed
    from backend.jobs import JobManager
    from robot.collision import CollisionWorld
    from robot.drivers.base import MoveReport, RobotDriver, RobotState
    from robot.model import ArmModel

__all__ = ["STILL_RAD_S", "CellMotion", "Pose", "Target"]

#: The arm counts as still when no joint turns faster than this, rad/s (0.06 deg/s).
STILL_RAD_S = 1e-3
#: Longest settle wait, seconds.
MAX_SETTLE_S = 60.0
#: Joint-space step between collision checks along a Cartesian line, radians.
LINE_CHECK_RAD = 0.05


@dataclass(frozen=True)
class Pose:
    """A flange target in the chapter's form (eq. 20) plus the roll about the approach axis.

    Attributes
    ----------
    x, y, z : float
        Flange position in the base frame, metres.
    u, w : float
        ``u = cos(q2 + q3 + q4)``, ``w = sin(q2 + q3 + q4)`` (the approach direction).
    roll : float
        Rotation about the approach axis (q5), radians.
    """

    x: float
    y: float
    z: float
    u: float
    w: float
    roll: float = 0.0

    def __post_init__(self) -> None:
        for name in ("x", "y", "z", "u", "w", "roll"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float | np.floating):
                raise ValueError(f"pose {name} must be a number, got {v!r}")
            if not math.isfinite(float(v)):
                raise ValueError(f"pose {name} must be finite, got {v!r}")
        if max(abs(self.x), abs(self.y), abs(self.z)) > 10.0:
            raise ValueError(f"pose position must be within 10 m of the base, got {self.xyz}")
        if abs(self.roll) > 4 * math.pi:
            raise ValueError(f"roll must be within +-4 pi rad, got {self.roll!r}")

    @property
    def xyz(self) -> tuple[float, float, float]:
        """The position, metres."""
        return (float(self.x), float(self.y), float(self.z))

    def as_tuple(self) -> tuple[float, float, float, float, float]:
        """``(x, y, z, u, w)``."""
        return (float(self.x), float(self.y), float(self.z), float(self.u), float(self.w))


#: Joints (array of shape (5,), radians) or a :class:`Pose`.
Target = ArrayLike | Pose


def _check_speed(speed: float) -> float:
    if isinstance(speed, bool) or not isinstance(speed, int | float | np.floating):
        raise InvalidInput(f"speed must be a number in [{MIN_SPEED}, 1], got {speed!r}")
    s = float(speed)
    if not (math.isfinite(s) and MIN_SPEED <= s <= 1.0):
        raise InvalidInput(f"speed must be in [{MIN_SPEED}, 1], got {speed!r}")
    return s


def _report_dict(report: MoveReport) -> dict[str, object]:
    return {
        "completed": report.completed,
        "reason": report.reason,
        "duration_s": report.duration_s,
        "final_joints": list(report.final_q),
        "final_error_rad": report.final_error_rad,
        "rms_tracking_error_rad": report.rms_tracking_error_rad,
        "max_tracking_error_rad": report.max_tracking_error_rad,
    }


class CellMotion:
    """Motion building blocks; mixed into :class:`~backend.cell.Cell`, which provides the
    attributes below."""

    driver: RobotDriver
    model: ArmModel
    jobs: JobManager
    feed: CameraFeed
    speed: float
    world: CollisionWorld | None

    # -- planning (synchronous: refuses before anything moves) -------------------------------
    def plan_move(
        self,
        target: Target,
        *,
        speed: float | None = None,
        path: Literal["joint", "line"] = "joint",
        world: CollisionWorld | None = None,
    ) -> JointTrajectory:
        """The trajectory from the arm's current joints to ``target``, checked for joint
        limits, reach and collisions (``world``, default the cell's); raises instead of
        returning a plan that must not run."""
        s = _check_speed(self.speed if speed is None else speed)
        q_now = np.asarray(self.driver.state.q, dtype=np.float64)
        if isinstance(target, Pose):
            if path == "joint":
                goal = ik(target.as_tuple(), roll=target.roll, seed=q_now, model=self.model)
                traj = plan_joint_move(q_now, goal, speed=s, model=self.model)
            elif path == "line":
                traj = plan_cartesian_line(
                    q_now, target.as_tuple(), roll=target.roll, speed=s, model=self.model
                )
            else:
                raise ValueError(f"path must be 'joint' or 'line', got {path!r}")
        else:
            if path != "joint":
                raise ValueError(f"a joint target moves along a joint path, got path={path!r}")
            arr = np.asarray(target)
            if arr.dtype == np.bool_ or arr.dtype.kind not in "iuf":
                raise ValueError(f"joints must be 5 numbers (radians), got {target!r}")
            goal = check_joints(arr.astype(np.float64).reshape(-1), self.model)
            traj = plan_joint_move(q_now, goal, speed=s, model=self.model)
        self._check_path(traj, world if world is not None else self.world, path)
        return traj

    def _check_path(self, traj: JointTrajectory, world: CollisionWorld | None, path: str) -> None:
        if world is None:
            return
        if path == "joint":  # a synchronised joint move follows the straight joint path
            hits = world.path_contacts(traj.start, traj.goal)
        else:
            hits = next(
                (c for q in _spaced(traj.q, LINE_CHECK_RAD) if (c := world.contacts(q))), []
            )
        if hits:
            raise PathBlocked(f"the move would bring the {hits[0]}; nothing moved", tuple(hits))

    def check_can_move(self) -> None:
        """Raise :class:`RobotBusy` if a motion would be refused now: the emergency stop is
        latched, or another job holds the arm."""
        if self.driver.state.estopped:
            raise RobotBusy("emergency stop is active: reset before moving")
        self.jobs.check_arm_free()

    @contextlib.contextmanager
    def _arm(self, what: str) -> Iterator[None]:
        """Hold the arm for one step: nothing to take when the calling job holds it."""
        if self.driver.state.estopped:
            raise RobotBusy("emergency stop is active: reset before moving")
        if self.jobs.holds_arm(current_job()):
            yield
            return
        with self.jobs.reserve_arm(what):
            yield

    def check_commandable(self) -> None:
        """Refuse to command a motion the driver's own state says must not be made: the
        e-stop latched (:class:`RobotBusy`) or the link to the controller down
        (:class:`LinkDown`; the fault campaign's motion audit found an inspection under way
        commanding its next move into a link already reported down)."""
        st = self.driver.state
        if st.estopped:
            raise RobotBusy("emergency stop is active: reset before moving")
        if not st.connected:
            raise LinkDown(f"the arm's link is down ({st.fault or 'disconnected'}): not moving")

    async def execute(self, traj: JointTrajectory) -> MoveReport:
        """Run a planned trajectory (the caller holds the arm); :class:`MoveAborted` unless
        it completes; nothing is commanded while :meth:`check_commandable` refuses."""
        self.check_commandable()
        report = await self.driver.move(traj)
        if not report.completed:
            raise MoveAborted(f"the move ended with {report.reason!r} before its goal", report)
        return report

    # -- the building blocks ---------------------------------------------------------------------
    async def move_to(
        self,
        target: Target,
        *,
        speed: float | None = None,
        path: Literal["joint", "line"] = "joint",
        world: CollisionWorld | None = None,
    ) -> MoveReport:
        """Move to ``target`` (joints, shape (5,), radians; or a :class:`Pose`).

        Parameters
        ----------
        target : array_like of shape (5,) or Pose
            Goal joints, or a flange pose solved by IK (the branch nearest the current joints).
        speed : float in [0.01, 1], optional
            Fraction of the arm's speed limits (default: the cell's speed).
        path : {"joint", "line"}
            Synchronised joint move, or (pose targets) a straight flange line.
        world : CollisionWorld, optional
            Obstacles to check the path against (default: the cell's; e.g. add a board box).

        Returns
        -------
        MoveReport
            The completed move.
        """
        with self._arm("a move_to call"):
            traj = self.plan_move(target, speed=speed, path=path, world=world)
            return await self.execute(traj)

    async def settle(
        self,
        *,
        wait_s: float = 0.0,
        still_rad_s: float = STILL_RAD_S,
        timeout_s: float = 3.0,
    ) -> RobotState:
        """Wait ``wait_s``, then until the arm is not moving and no joint turns faster than
        ``still_rad_s``; returns that state.  Raises :class:`NotStill` after ``timeout_s``
        (the controller may still be damping the end of a move: a moving camera blurs and
        its encoders disagree with the exposure)."""
        for name, v, hi in (
            ("wait_s", wait_s, MAX_SETTLE_S),
            ("still_rad_s", still_rad_s, 1.0),
            ("timeout_s", timeout_s, MAX_SETTLE_S),
        ):
            if isinstance(v, bool) or not isinstance(v, int | float) or not 0.0 <= v <= hi:
                raise ValueError(f"{name} must be in [0, {hi:g}], got {v!r}")
        if wait_s > 0:
            await asyncio.sleep(wait_s)
        deadline = time.monotonic() + timeout_s
        while True:
            state = self.driver.state
            fastest = float(np.abs(np.asarray(state.qd, dtype=np.float64)).max())
            if not state.moving and fastest < still_rad_s:
                return state
            if time.monotonic() >= deadline:
                raise NotStill(
                    f"the arm is not still after {timeout_s:g} s (fastest joint "
                    f"{fastest:.3g} rad/s, moving={state.moving})"
                )
            await asyncio.sleep(0.01)

    async def next_frame(self, *, after: float, timeout_s: float = 10.0) -> Frame:
        """The first camera frame exposed strictly after ``after`` (``time.monotonic()``)."""
        return await self.feed.next_frame(after=after, timeout_s=timeout_s)

    async def _look_frame(self, *, after: float, timeout_s: float) -> Frame:
        """The frame a look takes: the first exposed after ``after``; from a recorded cell
        (a camera replaying in step mode) the recording's image due now, recognised by its
        ``meta["replay_step"]``, after which the camera moves on to the next image (the live
        view shows the image the next look will take)."""
        cam: Any = self.feed.camera  # a replaying camera has step, replay_step, advance
        if getattr(cam, "step", False) is not True or not callable(getattr(cam, "advance", None)):
            return await self.next_frame(after=after, timeout_s=timeout_s)
        want = int(cam.replay_step)
        frame = await self._replay_frame(want, after=after, timeout_s=timeout_s)
        cam.advance()
        return frame

    async def _replay_frame(self, want: int, *, after: float, timeout_s: float) -> Frame:
        """The first frame of replay step ``want`` exposed after ``after``."""
        deadline = time.monotonic() + timeout_s
        frame = await self.next_frame(after=after, timeout_s=timeout_s)
        while int(frame.meta.get("replay_step", want)) < want:
            left = deadline - time.monotonic()
            if left <= 0.0:
                raise CameraError(f"the recorded camera did not move on to image {want} "
                                  f"within {timeout_s:g} s")  # fmt: skip
            frame = await self.next_frame(after=frame.stamp_s, timeout_s=left)
        return frame

    async def look(
        self,
        target: Target | None = None,
        *,
        speed: float | None = None,
        path: Literal["joint", "line"] = "joint",
        world: CollisionWorld | None = None,
        settle_s: float = 0.05,
        timeout_s: float = 10.0,
    ) -> Frame:
        """Move to ``target`` (stay when None), settle, and return a frame exposed after
        the arm was found still.

        The frame's ``robot_state`` is the source's own (the simulator knows it) or else
        the still state; ``meta["look"]`` holds the ``move_s``, ``settle_s`` and
        ``acquire_s`` durations (wall seconds).
        """
        t0 = time.monotonic()
        if target is not None and self.feed.failing:
            # No move for a picture the camera cannot take (the arm holds where it is).
            raise CameraError(f"the camera is failing, not moving to look: {self.feed.failing}")
        with self._arm("a look call"):
            if target is not None:
                traj = self.plan_move(target, speed=speed, path=path, world=world)
                await self.execute(traj)
            t1 = time.monotonic()
            still = await self.settle(wait_s=settle_s)
            t2 = time.monotonic()
            frame = await self._look_frame(after=t2, timeout_s=timeout_s)
        t3 = time.monotonic()
        meta = {
            **frame.meta,
            "look": {"move_s": t1 - t0, "settle_s": t2 - t1, "acquire_s": t3 - t2},
        }
        state = frame.robot_state if frame.robot_state is not None else still
        return dataclasses.replace(frame, robot_state=state, meta=meta)


def _spaced(q: NDArray[np.float64], step_rad: float) -> Iterator[NDArray[np.float64]]:
    """Rows of ``q`` at least ``step_rad`` apart (largest joint change), and the last."""
    last = None
    for row in q:
        if last is None or float(np.abs(row - last).max()) >= step_rad:
            last = row
            yield row
    if last is not None and not np.array_equal(last, q[-1]):
        yield q[-1]
