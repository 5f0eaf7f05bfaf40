"""Pick and place with a suction cup: the motion sequence as a pure planner, and its execution.

Given where an object is (``T_base_obj``: footprint centre on the belt, z up) and how tall it
is, :func:`plan_pick_place` plans the chapter's manipulation (section 1: "move the robot to
the desired pose relative to the object", then sort it):

1. ``approach``: a joint move to the pre-grasp pose, the cup's lip ``approach_m`` above the
   grasp point (and above the object's top), pointing down the object's z axis;
2. ``descend``: a straight line down (:func:`robot.trajectory_cartesian.plan_cartesian_line`)
   until the lip is ``press_m`` into the surface;
3. ``grip`` (suction on), then ``lift``: straight up until the part's bottom clears every
   obstacle (the highest box of the collision world) by ``clearance_m``;
4. ``transfer``: a joint move to above the bin, then (if lower) a straight line down to the
   drop pose, the part's footprint centre over the bin's drop point and its bottom
   ``drop_clearance_m`` above the rim;
5. ``release`` (suction off), ``retreat`` straight up and ``return`` to ``q_return``.

Every pose passes the closed-form IK within the joint ranges, every path the collision
model (:class:`robot.collision.CollisionWorld`, sampled), with the held part represented by
a sphere round its bounding box below the cup; the object being picked is an obstacle for
the approach only.  Failures raise :class:`~robot.errors.Unreachable` naming the stage and
the reason.  The 5-DOF arm approaches only vertically (its approach axis stays in the
column's plane), so objects must stand upright (z within ``max_tilt_deg`` of vertical).

:func:`execute_pick_place` runs a plan on any :class:`~robot.drivers.base.RobotDriver` with
a gripper, checking every move's report and that the part is held after gripping.
"""

from __future__ import annotations

import asyncio
import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robot.collision import Box, CollisionWorld
from robot.drivers.base import GripReport, MoveReport, RobotDriver
from robot.errors import JointLimitsBlock, OutOfReach, Unreachable
from robot.kinematics import T_base_ee, ik
from robot.model import ASEA, ArmModel, check_joints
from robot.trajectory import JointTrajectory, plan_joint_move
from robot.trajectory_cartesian import plan_cartesian_line

__all__ = [
    "T_EE_SUCTION_CUP",
    "PickOutcome",
    "PickPlan",
    "PickStep",
    "execute_pick_place",
    "execute_search_pick_place",
    "plan_pick_place",
    "plan_pick_place_at_roll",
    "tool_flange_pose",
]


def _cup() -> NDArray[np.float64]:
    T = np.eye(4)
    T[:3, 3] = (-0.05, 0.0, 0.12)
    T.setflags(write=False)
    return T


#: The suction cup's lip on the flange: 50 mm along ``-x_ee`` (opposite the camera), 120 mm
#: past the flange face, its axis along the approach axis.
T_EE_SUCTION_CUP = _cup()


@dataclass(frozen=True)
class PickStep:
    """One step of a plan: a move (``trajectory``), or a gripper action (``grip``)."""

    name: str
    trajectory: JointTrajectory | None = None
    grip: bool | None = None


@dataclass(frozen=True)
class PickPlan:
    """A planned pick and place.

    Attributes
    ----------
    steps : tuple of PickStep
        In order: approach, descend, grip, lift, transfer[, lower], release, retreat, return.
    q_grasp, q_drop : ndarray of shape (5,)
        Joints at the grasp and at the release.
    T_base_lip_grasp : ndarray of shape (4, 4)
        The cup's lip at the grasp.
    duration_s : float
        Sum of the moves' durations.
    """

    steps: tuple[PickStep, ...]
    q_grasp: NDArray[np.float64]
    q_drop: NDArray[np.float64]
    T_base_lip_grasp: NDArray[np.float64]
    duration_s: float = field(default=0.0)


def _R_down(q1: float, roll: float) -> NDArray[np.float64]:
    """Flange rotation pointing straight down (phi = -pi/2) at azimuth q1 with roll q5."""
    c1, s1, c5, s5 = math.cos(q1), math.sin(q1), math.cos(roll), math.sin(roll)
    xa = np.array([-c1, -s1, 0.0])
    ya = np.array([-s1, c1, 0.0])
    za = np.array([0.0, 0.0, -1.0])
    return np.stack([c5 * xa + s5 * ya, -s5 * xa + c5 * ya, za], axis=-1)


def tool_flange_pose(
    p_lip: ArrayLike, *, roll_rad: float = 0.0, T_ee_tool: ArrayLike = T_EE_SUCTION_CUP
) -> tuple[float, float, float, float, float]:
    """Chapter pose ``(x, y, z, u, w)`` of the flange, pointing down, with the tool's tip at
    ``p_lip`` (the flange's azimuth and the tool's offset are solved together by
    fixed-point iteration: the offset turns with the azimuth)."""
    p = np.asarray(p_lip, dtype=np.float64)
    t = np.asarray(T_ee_tool, dtype=np.float64)[:3, 3]
    q1 = math.atan2(p[1], p[0])
    for _ in range(50):
        f = p - _R_down(q1, roll_rad) @ t
        q1_new = math.atan2(f[1], f[0])
        if abs(math.remainder(q1_new - q1, 2 * math.pi)) < 1e-13:
            break
        q1 = q1_new
    f = p - _R_down(q1, roll_rad) @ t
    return (float(f[0]), float(f[1]), float(f[2]), 0.0, -1.0)


@dataclass(frozen=True)
class _HeldPart:
    """The part on the cup for collision checks: its footprint centre in the cup's frame
    (fixed while it is held: the weld), its half-width and height."""

    centre_cup: NDArray[np.float64]
    radius: float
    height: float

    def box(self, T_base_cup: NDArray[np.float64]) -> Box:
        c = T_base_cup[:3, :3] @ self.centre_cup + T_base_cup[:3, 3]
        r = self.radius
        return Box(
            "held part", (c[0] - r, c[1] - r, c[2]), (c[0] + r, c[1] + r, c[2] + self.height)
        )


def _box_gap(a: Box, b: Box) -> float:
    """Distance between two axis-aligned boxes (0 when they touch or overlap)."""
    lo_a, hi_a = np.asarray(a.lower), np.asarray(a.upper)
    lo_b, hi_b = np.asarray(b.lower), np.asarray(b.upper)
    d = np.maximum(np.maximum(lo_b - hi_a, lo_a - hi_b), 0.0)
    return float(np.linalg.norm(d))


def _check_path(
    what: str,
    traj: JointTrajectory,
    world: CollisionWorld,
    *,
    part: tuple[NDArray[np.float64], _HeldPart] | None,
    support_z: float | None = None,
    step_rad: float = 0.03,
) -> None:
    """Raise Unreachable if the arm (or the held part) comes near an obstacle on ``traj``.

    ``support_z``: the part is being lifted off a surface at this height; only its portion
    above the surface (plus the clearance) is checked.
    """
    q = traj.q
    dq = np.abs(np.diff(q, axis=0)).max(axis=1) if len(q) > 1 else np.zeros(0)
    keep = [0]
    acc = 0.0
    for i, d in enumerate(dq, start=1):
        acc += d
        if acc >= step_rad or i == len(q) - 1:
            keep.append(i)
            acc = 0.0
    hits = world.collides_many(q[keep])
    for k, i in enumerate(keep):
        contacts = world.contacts(q[i]) if hits[k] else []
        if contacts:
            raise Unreachable(
                f"{what}: collision at {100 * i / max(len(q) - 1, 1):.0f} % of the move: "
                + "; ".join(str(c) for c in contacts[:3])
            )
        if part is not None:
            T_tool, held = part
            pb = held.box(T_base_ee(q[i]) @ T_tool)
            if support_z is not None:  # leaving the surface it stood on
                z0 = max(pb.lower[2], support_z + world.clearance_m + 1e-3)
                pb = Box(pb.name, (pb.lower[0], pb.lower[1], min(z0, pb.upper[2])), pb.upper)
            for box in world.boxes:
                gap = _box_gap(pb, box)
                if gap < world.clearance_m:
                    raise Unreachable(
                        f"{what}: the held part comes {gap * 1e3:.0f} mm from the {box.name} "
                        f"at {100 * i / max(len(q) - 1, 1):.0f} % of the move"
                    )
            if pb.lower[2] - world.floor_z_m < world.clearance_m:
                raise Unreachable(f"{what}: the held part comes near the floor")


def _roll_candidates(
    T: NDArray[np.float64], g_obj: NDArray[np.float64], model: ArmModel
) -> list[float]:
    """Flange rolls to try for a grasp at ``g_obj`` (object frame) of the object at ``T``.

    The camera and the flange sit on the ``+x_ee`` side of the cup (:data:`T_EE_SUCTION_CUP`),
    so for a grasp off the footprint centre the tool is turned to put them *outward*, over
    the side of the grasp point away from the rest of the part: ``x_ee`` along the grasp's
    horizontal offset.  Pointing down (:func:`_R_down`), ``x_ee`` has the azimuth
    ``q1 - q5 + pi``, so the wanted roll is ``q5 = q1 + pi - alpha`` (``alpha`` the offset's
    azimuth, ``q1`` the azimuth of the grasp point seen from the base).  Then rolls ever
    further from it, 30 degrees apart, within the joint range.  A centred grasp tries roll 0
    first (the camera tangential to the column's plane).
    """
    off = T[:3, :3] @ np.array([g_obj[0], g_obj[1], 0.0])
    grasp = T[:3, :3] @ g_obj + T[:3, 3]
    if math.hypot(off[0], off[1]) < 0.005:
        want = 0.0
    else:
        q1 = math.atan2(grasp[1], grasp[0])
        want = math.remainder(q1 + math.pi - math.atan2(off[1], off[0]), 2 * math.pi)
    lo, hi = float(model.lower[4]), float(model.upper[4])
    out: list[float] = []
    for k in (0, 1, -1, 2, -2, 3, -3, 4, -4, 5, -5, 6):
        r = math.remainder(want + k * math.pi / 6, 2 * math.pi)
        if lo <= r <= hi and all(abs(r - o) > 1e-6 for o in out):
            out.append(r)
    return out


def plan_pick_place(
    q_start: ArrayLike,
    T_base_obj: ArrayLike,
    object_height_m: float,
    drop_point: ArrayLike,
    *,
    roll_rad: float | None = None,
    grasp_obj: ArrayLike | None = None,
    model: ArmModel = ASEA,
    **options: object,
) -> PickPlan:
    """Plan picking the object at ``T_base_obj`` and dropping it at ``drop_point``.

    With ``roll_rad`` given, that flange roll is used (:func:`plan_pick_place_at_roll`, whose
    parameters this takes as well).  Without it (the default), the rolls of
    :func:`_roll_candidates` are tried in turn (camera and flange turned away from the part
    over an off-centre grasp point) and the first plan clearing every check is returned;
    if none does, the :class:`~robot.errors.Unreachable` of the preferred roll is raised,
    naming the rolls tried.
    """
    if roll_rad is not None:
        return plan_pick_place_at_roll(q_start, T_base_obj, object_height_m, drop_point,
                                       roll_rad=roll_rad, grasp_obj=grasp_obj, model=model,
                                       **options)  # type: ignore[arg-type]  # fmt: skip
    T = np.asarray(T_base_obj, dtype=np.float64)
    if T.shape != (4, 4) or not np.isfinite(T).all():
        raise ValueError(
            f"T_base_obj must be a finite 4x4 matrix, got {np.asarray(T_base_obj).tolist()}"
        )
    h = object_height_m
    if isinstance(h, bool) or not (isinstance(h, int | float) and 0.0 < h <= 0.5):
        raise ValueError(f"object_height_m must be in (0, 0.5] m, got {h!r}")
    g = (
        np.array([0.0, 0.0, float(h)])
        if grasp_obj is None
        else np.asarray(grasp_obj, dtype=np.float64).reshape(3)
    )
    if not np.isfinite(g).all():
        raise ValueError(f"grasp_obj must be 3 finite numbers, got {grasp_obj!r}")
    first: Unreachable | None = None
    rolls = _roll_candidates(T, g, model)
    for r in rolls:
        try:
            return plan_pick_place_at_roll(q_start, T, h, drop_point, roll_rad=r,
                                           grasp_obj=grasp_obj, model=model, **options)  # type: ignore[arg-type]  # fmt: skip
        except Unreachable as exc:
            first = first or exc
    assert first is not None
    msg = f"{first.detail} (preferred roll {math.degrees(rolls[0]):.0f} deg; {len(rolls)} rolls tried)"
    if isinstance(first, JointLimitsBlock):
        raise JointLimitsBlock(msg, first.joints) from first
    raise type(first)(msg) from first


def plan_pick_place_at_roll(
    q_start: ArrayLike,
    T_base_obj: ArrayLike,
    object_height_m: float,
    drop_point: ArrayLike,
    *,
    object_radius_m: float = 0.18,
    grasp_obj: ArrayLike | None = None,
    world: CollisionWorld | None = None,
    T_ee_tool: ArrayLike = T_EE_SUCTION_CUP,
    roll_rad: float = 0.0,
    approach_m: float = 0.08,
    press_m: float = 0.004,
    clearance_m: float = 0.05,
    drop_clearance_m: float = 0.03,
    q_return: ArrayLike | None = None,
    transit_max_z_m: float = 0.9,
    speed: float = 0.5,
    max_tilt_deg: float = 2.0,
    model: ArmModel = ASEA,
    from_grasp: bool = False,
) -> PickPlan:
    """Plan picking the object at ``T_base_obj`` and dropping it at ``drop_point`` with the
    flange rolled by ``roll_rad``.

    ``from_grasp``: the arm is at the grasp already, the part held (``q_start``, e.g. after
    the guarded descent of :func:`execute_search_pick_place`): the plan starts with the
    lift (no approach, descent or grip step); ``q_return`` should then be given.

    Parameters
    ----------
    q_start : array_like of shape (5,)
        Where the arm is.
    T_base_obj : array_like of shape (4, 4)
        Object frame: footprint centre on its support, z up.
    object_height_m : float
        Height of the object, metres (in (0, 0.5]).
    drop_point : array_like of shape (3,)
        Centre of the bin's opening at rim height, base frame.
    object_radius_m : float
        Half-width of the object (its obstacle box for the approach, its sphere when held).
    grasp_obj : array_like of shape (3,), optional
        Where the cup seals, object frame; default the top face's centre
        ``(0, 0, object_height_m)``.
    world : CollisionWorld, optional
        The cell's obstacles (default: the floor only).
    T_ee_tool : array_like of shape (4, 4)
        The cup's lip on the flange (its z axis along the approach axis).
    roll_rad : float
        Flange roll q5 during the pick.
    approach_m, press_m, clearance_m, drop_clearance_m : float
        Pre-grasp height above the grasp point, how far the lip is pressed into the surface,
        the part's clearance above every obstacle in transit, and above the rim at the drop.
    q_return : array_like of shape (5,), optional
        Where to go at the end (default ``q_start``).
    transit_max_z_m : float
        Obstacles up to this height are flown over in transit; taller ones (fences,
        columns) are not, the collision check keeps the arm and the part clear of them.
    speed : float in (0, 1]
        Fraction of the joint and Cartesian speed limits.
    max_tilt_deg : float
        Largest tilt of the object's z axis from vertical.
    model : ArmModel

    Returns
    -------
    PickPlan

    Raises
    ------
    ValueError
        Malformed or non-finite inputs, values out of range.
    Unreachable
        A pose or path is out of reach, blocked by a joint range or collides; the message
        names the stage.
    """
    qs = check_joints(np.asarray(q_start, dtype=np.float64).reshape(5), model)
    T = np.asarray(T_base_obj, dtype=np.float64)
    if T.shape != (4, 4) or not np.isfinite(T).all():
        raise ValueError(
            f"T_base_obj must be a finite 4x4 matrix, got {np.asarray(T_base_obj).tolist()}"
        )
    R = T[:3, :3]
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
        raise ValueError(f"T_base_obj must be a rigid transform, got {T.tolist()}")
    if isinstance(object_height_m, bool) or not (
        isinstance(object_height_m, int | float) and 0.0 < object_height_m <= 0.5
    ):
        raise ValueError(f"object_height_m must be in (0, 0.5] m, got {object_height_m!r}")
    drop = np.asarray(drop_point, dtype=np.float64).reshape(-1)
    if drop.shape != (3,) or not np.isfinite(drop).all() or np.linalg.norm(drop[:2]) > 2.0:
        raise ValueError(f"drop_point must be 3 finite numbers within 2 m, got {drop_point!r}")
    for name, v, lo, hi in (
        ("object_radius_m", object_radius_m, 0.0, 0.5),
        ("approach_m", approach_m, 0.0, 0.5),
        ("press_m", press_m, 0.0, 0.03),
        ("clearance_m", clearance_m, 0.0, 0.5),
        ("drop_clearance_m", drop_clearance_m, 0.0, 0.5),
        ("roll_rad", roll_rad, -math.pi, math.pi),
        ("max_tilt_deg", max_tilt_deg, 0.0, 10.0),
        ("transit_max_z_m", transit_max_z_m, 0.0, 2.0),
    ):
        if isinstance(v, bool) or not (
            isinstance(v, int | float) and math.isfinite(v) and lo <= v <= hi
        ):
            raise ValueError(f"{name} must be in [{lo}, {hi}], got {v!r}")
    tilt = math.degrees(math.acos(max(-1.0, min(1.0, float(R[2, 2])))))
    if tilt > max_tilt_deg:
        raise Unreachable(
            f"the object's z axis is {tilt:.1f} deg off vertical (limit {max_tilt_deg:g} deg): "
            "the 5-DOF arm picks only from straight above"
        )
    Tt = np.asarray(T_ee_tool, dtype=np.float64)
    if Tt.shape != (4, 4) or abs(float(Tt[2, 2]) - 1.0) > 1e-9:
        raise ValueError("T_ee_tool must be a 4x4 transform with its z axis along the flange's")
    g_obj = (
        np.array([0.0, 0.0, float(object_height_m)])
        if grasp_obj is None
        else np.asarray(grasp_obj, dtype=np.float64).reshape(3)
    )
    if not np.isfinite(g_obj).all() or not 0.0 <= g_obj[2] <= object_height_m + 1e-9:
        raise ValueError(
            f"grasp_obj must be a finite point within the object's height, got {grasp_obj!r}"
        )
    q_end = qs if q_return is None else check_joints(np.asarray(q_return, float).reshape(5), model)
    obstacles = world or CollisionWorld(model=model)
    p_obj = T[:3, 3]
    r_obj = float(object_radius_m)
    obj_box = Box(
        "object",
        (p_obj[0] - r_obj, p_obj[1] - r_obj, p_obj[2]),
        (p_obj[0] + r_obj, p_obj[1] + r_obj, p_obj[2] + object_height_m),
    )
    grasp = T[:3, :3] @ g_obj + T[:3, 3]
    grasp_z = float(g_obj[2]) - press_m  # lip height above the part's bottom when held
    off = T[:3, :3] @ np.array([g_obj[0], g_obj[1], 0.0])
    top_z = max(
        [b.upper[2] for b in obstacles.boxes if b.upper[2] <= transit_max_z_m]
        + [obstacles.floor_z_m]
    )
    z_transit = max(top_z + clearance_m + grasp_z, grasp[2] + approach_m)
    z_transit = max(z_transit, float(p_obj[2]) + object_height_m + clearance_m)

    def solve(
        p_lip: NDArray[np.float64], seed: NDArray[np.float64], stage: str
    ) -> NDArray[np.float64]:
        pose = tool_flange_pose(p_lip, roll_rad=roll_rad, T_ee_tool=Tt)
        try:
            return ik(pose, roll=roll_rad, seed=seed, model=model)
        except JointLimitsBlock as e:
            raise JointLimitsBlock(f"{stage}: {e.detail}", e.joints) from None
        except OutOfReach as e:
            raise OutOfReach(f"{stage}: {e.detail}") from None

    def line(q0: NDArray[np.float64], p_lip: NDArray[np.float64], stage: str) -> JointTrajectory:
        try:
            return plan_cartesian_line(
                q0,
                tool_flange_pose(p_lip, roll_rad=roll_rad, T_ee_tool=Tt),
                roll=roll_rad,
                speed=speed,
                model=model,
            )
        except Unreachable as e:
            raise Unreachable(f"{stage}: {e.detail}") from None

    steps: list[PickStep] = []
    if from_grasp:
        q_grasp = qs
        p_grasp = (T_base_ee(qs, model) @ Tt)[:3, 3]
    else:
        # 1. approach (the object itself is an obstacle).
        p_pre = grasp + np.array([0.0, 0.0, approach_m])
        p_pre[2] = max(p_pre[2], float(p_obj[2]) + object_height_m + approach_m)
        q_pre = solve(p_pre, qs, "pre-grasp pose")
        t_app = plan_joint_move(qs, q_pre, speed=speed, model=model)
        _check_path("approach", t_app, obstacles.with_boxes(obj_box), part=None)
        steps.append(PickStep("approach", t_app))
        # 2. descend (touching the object: it is not an obstacle now).
        p_grasp = grasp - np.array([0.0, 0.0, press_m])
        t_down = line(q_pre, p_grasp, "descent to the grasp")
        _check_path("descent", t_down, obstacles, part=None)
        q_grasp = t_down.goal
        steps += [PickStep("descend", t_down), PickStep("grip", grip=True)]
    T_cup_grasp = T_base_ee(q_grasp, model) @ Tt
    centre_cup = T_cup_grasp[:3, :3].T @ (p_obj - T_cup_grasp[:3, 3])
    part = (Tt, _HeldPart(centre_cup, r_obj, float(object_height_m)))
    # 3. lift to the transit height.
    p_lift = np.array([p_grasp[0], p_grasp[1], z_transit])
    t_up = line(q_grasp, p_lift, "lift")
    _check_path("lift", t_up, obstacles, part=part, support_z=float(p_obj[2]))
    steps.append(PickStep("lift", t_up))
    # 4. transfer over the bin, lower to the drop pose.
    z_drop = float(drop[2]) + drop_clearance_m + grasp_z
    # The part turns with the flange about the vertical (by the change of q1): its
    # footprint centre's offset from the lip is turned with it, found by iteration.
    q_over = t_up.goal
    for _ in range(30):
        dq1 = float(q_over[0] - q_grasp[0])
        c, s_ = math.cos(dq1), math.sin(dq1)
        off_d = np.array([c * off[0] - s_ * off[1], s_ * off[0] + c * off[1]])
        p_over = np.array([drop[0] + off_d[0], drop[1] + off_d[1], max(z_drop, z_transit)])
        q_prev, q_over = q_over, solve(p_over, t_up.goal, "above the bin")
        if abs(q_over[0] - q_prev[0]) < 1e-12:
            break
    t_tr = plan_joint_move(t_up.goal, q_over, speed=speed, model=model)
    _check_path("transfer", t_tr, obstacles, part=part)
    steps.append(PickStep("transfer", t_tr))
    q_drop = q_over
    lowered = False
    if z_drop < p_over[2] - 1e-6:
        # Down to the drop height, or (out of reach there: a far bin, a turned part) as low
        # as the arm gets in five steps towards the transit height; the part falls the rest.
        for z_try in np.linspace(z_drop, p_over[2], 6)[:-1]:
            try:
                t_low = line(
                    q_over, np.array([p_over[0], p_over[1], z_try]), "lowering into the bin"
                )
                _check_path("lowering", t_low, obstacles, part=part)
            except Unreachable:
                continue
            steps.append(PickStep("lower", t_low))
            q_drop = t_low.goal
            lowered = True
            break
    steps.append(PickStep("release", grip=False))
    # 5. retreat and return.
    q_last = q_drop
    if lowered:
        t_ret = line(q_drop, p_over, "retreat")
        _check_path("retreat", t_ret, obstacles, part=None)
        steps.append(PickStep("retreat", t_ret))
        q_last = t_ret.goal
    t_home = plan_joint_move(q_last, q_end, speed=speed, model=model)
    _check_path("return", t_home, obstacles, part=None)
    steps.append(PickStep("return", t_home))
    T_lip = T_base_ee(q_grasp, model) @ Tt
    total = sum(s.trajectory.duration_s for s in steps if s.trajectory is not None)
    return PickPlan(tuple(steps), q_grasp, q_drop, T_lip, float(total))


@dataclass(frozen=True)
class PickOutcome:
    """How executing a plan went.

    Attributes
    ----------
    ok : bool
        True if every step completed and the part was held until the release.
    stage : str
        The last step reached (the failing one when ``ok`` is False).
    reason : str
        ``"done"`` or why it stopped.
    grip : GripReport or None
        The report of the grip step.
    moves : tuple of MoveReport
        Reports of the moves executed, in order.
    """

    ok: bool
    stage: str
    reason: str
    grip: GripReport | None
    moves: tuple[MoveReport, ...]


async def execute_pick_place(driver: RobotDriver, plan: PickPlan) -> PickOutcome:
    """Run ``plan`` on ``driver``: each move must complete, the grip must hold a part.

    If the grip holds nothing, the suction is switched off and the arm goes back up the
    descent's line (the failure is reported, the arm left safe above the object).  A move
    that does not complete (stop, e-stop, fault) ends the run at once with its reason; the
    gripper keeps its state (a part is not dropped where it happens to be).
    """
    moves: list[MoveReport] = []
    grip: GripReport | None = None
    descent: JointTrajectory | None = None
    for step in plan.steps:
        if step.trajectory is not None:
            report = await driver.move(step.trajectory)
            moves.append(report)
            if not report.completed:
                return PickOutcome(False, step.name, report.reason, grip, tuple(moves))
            if step.name == "descend":
                descent = step.trajectory
            continue
        if step.grip:
            grip = await driver.grip(True)
            if not grip.holding:
                await driver.grip(False)
                if descent is not None:
                    back = JointTrajectory(
                        descent.t_s[-1] - descent.t_s[::-1], descent.q[::-1], -descent.qd[::-1]
                    )
                    moves.append(await driver.move(back))
                return PickOutcome(
                    False, step.name, f"no part held: {grip.detail}", grip, tuple(moves)
                )
        else:
            await driver.grip(False)
    return PickOutcome(True, plan.steps[-1].name, "done", grip, tuple(moves))


async def execute_search_pick_place(
    driver: RobotDriver,
    T_base_obj: ArrayLike,
    drop_point: ArrayLike,
    *,
    max_height_m: float,
    object_radius_m: float = 0.18,
    world: CollisionWorld | None = None,
    q_return: ArrayLike | None = None,
    min_grasp_m: float = 0.01,
    speed: float = 0.3,
    model: ArmModel = ASEA,
    poll_s: float = 0.005,
    offsets_m: tuple[tuple[float, float], ...] = (
        (0.0, 0.0),
        (0.03, 0.0),
        (0.0, 0.03),
        (-0.03, 0.0),
        (0.0, -0.03),
    ),
) -> tuple[PickOutcome, float | None]:
    """Pick an object of unknown height with a guarded descent, and drop it at ``drop_point``.

    What a cell does with a part it cannot name (the reject bin): its footprint centre is
    known from the top view, its height is not.  The cup approaches above ``max_height_m``
    (the tallest object the station admits; the object's box up to it is an obstacle), the
    suction is switched on, and the cup comes straight down the object's axis towards
    ``min_grasp_m`` above the support; the vacuum switch (``state.holding``) stops the
    descent the moment the cup seals (a *search* or guarded move, as industrial controllers
    run for stacks of unknown height).  Nothing sealing (a hole, a steep face), the suction is
    switched off, the arm backs up and the next of ``offsets_m`` (object frame, from the
    footprint centre) is tried.  The lift, transfer and release are then planned from where
    the arm stopped, with the height found, and run as :func:`execute_pick_place` does.

    Returns
    -------
    (PickOutcome, height)
        The outcome (``stage`` "descend" with ``ok`` False when nothing sealed: the suction
        is switched off and the arm backs up) and the height found (lip height above the
        support at the seal), or None.

    Raises
    ------
    Unreachable
        The approach, the descent or the rest cannot be planned (nothing moved if it is the
        approach or the descent).
    """
    T = np.asarray(T_base_obj, dtype=np.float64)
    h_max = max_height_m
    if isinstance(h_max, bool) or not (isinstance(h_max, int | float) and 0.0 < h_max <= 0.5):
        raise ValueError(f"max_height_m must be in (0, 0.5] m, got {max_height_m!r}")
    if not (isinstance(min_grasp_m, int | float) and 0.0 <= min_grasp_m < h_max):
        raise ValueError(f"min_grasp_m must be in [0, max_height_m), got {min_grasp_m!r}")
    q0 = np.asarray(driver.state.q, dtype=np.float64)
    q_end = q0 if q_return is None else np.asarray(q_return, dtype=np.float64)
    obstacles = world or CollisionWorld(model=model)
    moves: list[MoveReport] = []
    grip: GripReport | None = None
    tried: list[str] = []
    planned = False
    for dx, dy in offsets_m:
        q_now = np.asarray(driver.state.q, dtype=np.float64)
        try:
            first = plan_pick_place(q_now, T, float(h_max), drop_point,
                                    object_radius_m=object_radius_m,
                                    grasp_obj=(dx, dy, float(h_max)), world=obstacles,
                                    q_return=q_end, speed=speed, model=model,
                                    press_m=0.0)  # fmt: skip
            t_app = first.steps[0].trajectory
            assert t_app is not None
            roll = float(t_app.goal[4])
            lowest = T[:3, :3] @ np.array([dx, dy, float(min_grasp_m)]) + T[:3, 3]
            t_down = plan_cartesian_line(
                t_app.goal, tool_flange_pose(lowest, roll_rad=roll), roll=roll,
                speed=0.2 * speed, model=model,
            )  # fmt: skip
            _check_path("search descent", t_down, obstacles, part=None)
        except Unreachable as e:
            tried.append(f"({dx * 1e3:+.0f}, {dy * 1e3:+.0f}) mm: {e.detail}")
            continue
        planned = True
        rep = await driver.move(t_app)
        moves.append(rep)
        if not rep.completed:
            return PickOutcome(False, "approach", rep.reason, None, tuple(moves)), None
        grip = await driver.grip(True)
        task = asyncio.ensure_future(driver.move(t_down))
        while not task.done():
            if driver.state.holding:
                await driver.stop()
                break
            await asyncio.sleep(poll_s)
        rep = await task
        moves.append(rep)
        if driver.state.holding:
            break
        await driver.grip(False)
        if not (rep.completed or rep.reason == "stopped"):
            return PickOutcome(False, "descend", rep.reason, grip, tuple(moves)), None
        back = plan_joint_move(
            np.asarray(driver.state.q, float), t_app.goal, speed=speed, model=model
        )
        moves.append(await driver.move(back))
        tried.append(f"({dx * 1e3:+.0f}, {dy * 1e3:+.0f}) mm: nothing sealed on the way down")
    else:
        if not planned:
            raise Unreachable("search pick: no grasp point could be planned: " + "; ".join(tried))
        return PickOutcome(False, "descend", "no part held: " + "; ".join(tried), grip,
                           tuple(moves)), None  # fmt: skip
    grip = GripReport(True, True, detail="part held (sealed during the search descent)")
    q_seal = np.asarray(driver.state.q, dtype=np.float64)
    lip = (T_base_ee(q_seal, model) @ T_EE_SUCTION_CUP)[:3, 3]
    height = float(np.clip(lip[2] - T[2, 3], 1e-3, h_max))
    rest = plan_pick_place_at_roll(q_seal, T, height, drop_point, object_radius_m=object_radius_m,
                                   grasp_obj=(lip - T[:3, 3]) @ T[:3, :3], world=obstacles,
                                   roll_rad=float(q_seal[4]), q_return=q_end, speed=speed,
                                   model=model, from_grasp=True, press_m=0.0)  # fmt: skip
    for step in rest.steps:
        if step.trajectory is not None:
            rep = await driver.move(step.trajectory)
            moves.append(rep)
            if not rep.completed:
                return PickOutcome(False, step.name, rep.reason, grip, tuple(moves)), height
        elif step.grip is False:
            await driver.grip(False)
    return PickOutcome(True, rest.steps[-1].name, "done", grip, tuple(moves)), height
