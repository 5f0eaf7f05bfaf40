"""Cartesian straight-line moves through the closed-form inverse kinematics.

The path: the flange position moves on the segment from the start to the goal position,
while the approach angle ``phi = q2 + q3 + q4`` and the roll q5 move linearly between their
start and goal values (so ``(u, w) = (cos phi, sin phi)`` stays a unit vector, and the
approach axis turns with the arm plane as the position moves round the column).  The path
parameter ``s`` follows the minimum-jerk time scaling :func:`robot.trajectory.quintic`.

Checks along the path, on a dense grid (``path_step_m``, ``path_step_rad``):

* every point has an IK solution within the joint ranges, else :class:`Unreachable` (the
  subclass of the reason) naming the fraction of the path and the point;
* the solution stays on one branch and no joint jumps more than ``max_joint_step_rad``
  between neighbouring points (a jump means the line passes through or near a singular or
  range-wrapping configuration), else :class:`Unreachable` naming where and which joint.

Time: the duration is the smallest that keeps the Cartesian speed and acceleration (and the
angular ones of ``phi`` and the roll) within the given limits and, from the path derivatives
``dq/ds``, ``d2q/ds2``, every joint's velocity ``q' s'`` and acceleration
``q'' s'^2 + q' s''`` within the model's limits (both scale as ``1/T`` and ``1/T^2``, so one
pass finds ``T``; the sampled result is verified and ``T`` stretched if interpolation pushes
a sample over).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from robot.errors import JointLimitsBlock, Unreachable
from robot.kinematics.analytic import BRANCHES, check_pose, ik
from robot.kinematics.batch import ik_batch_branches
from robot.kinematics.forward import fk
from robot.model import ASEA, ArmModel, check_joints
from robot.trajectory import (
    QUINTIC_PEAK_ACCELERATION,
    QUINTIC_PEAK_VELOCITY,
    JointTrajectory,
    _check_speed_rate,
    check_plan_size,
    quintic,
)

__all__ = ["plan_cartesian_line"]

_MAX_DENSE = 200_000


def _located(e: Unreachable, where: str) -> Unreachable:
    """The same kind of failure, with its place on the path prefixed."""
    detail = f"{where}: {e.detail}"
    if isinstance(e, JointLimitsBlock):
        return JointLimitsBlock(detail, e.joints)
    return type(e)(detail)


def plan_cartesian_line(
    q_start: ArrayLike,
    pose_goal: ArrayLike,
    *,
    roll: float | None = None,
    speed: float = 1.0,
    rate_hz: float = 100.0,
    max_linear_speed_m_s: float = 0.25,
    max_linear_acceleration_m_s2: float = 0.5,
    max_angular_speed_rad_s: float = 0.75,
    max_angular_acceleration_rad_s2: float = 1.5,
    path_step_m: float = 1e-3,
    path_step_rad: float = math.radians(0.1),
    max_joint_step_rad: float = 0.05,
    model: ArmModel = ASEA,
) -> JointTrajectory:
    """Straight-line flange move from the configuration ``q_start`` to a chapter pose.

    Parameters
    ----------
    q_start : array_like of shape (5,)
        Current joints, radians (checked against the ranges); the line starts at its pose.
    pose_goal : array_like of 5 floats
        Goal ``(x, y, z, u, w)`` as for :func:`robot.kinematics.ik`.
    roll : float, optional
        Goal roll about the approach axis, radians; default: keep the start's q5.
    speed : float in [MIN_SPEED, 1]
        Fraction of every speed limit (Cartesian and joint); accelerations scale with
        ``speed**2``.
    rate_hz : float
        Sampling rate of the returned table.
    max_linear_speed_m_s, max_linear_acceleration_m_s2 : float
        Limits on the flange's speed and acceleration along the line at ``speed = 1``
        (defaults derated for an eye-in-hand camera).
    max_angular_speed_rad_s, max_angular_acceleration_rad_s2 : float
        The same for the approach angle and the roll.
    path_step_m, path_step_rad : float
        Spacing of the dense grid on which the path is checked and differentiated.
    max_joint_step_rad : float
        Largest joint change allowed between neighbouring grid points before the path is
        declared discontinuous.
    model : ArmModel
        Geometry, ranges and joint limits.

    Returns
    -------
    JointTrajectory
        Starts exactly at ``q_start`` and ends at the goal's IK solution nearest to it, with
        analytic-in-``s`` velocities and accelerations within the joint limits.

    Raises
    ------
    ValueError
        Bad pose, speed, rate or limits.
    TrajectoryTooLong
        The line would last longer than ``robot.trajectory.MAX_DURATION_S`` or need more
        than ``MAX_SAMPLES`` samples (checked before the table is built).
    JointLimitError
        ``q_start`` is outside the ranges.
    OutOfReach, JointLimitsBlock
        The goal, or a point on the line, has no solution within the ranges; the message
        says where (fraction of the path and the point) and why.
    Unreachable
        The IK solution jumps (branch change or a joint moving more than
        ``max_joint_step_rad`` between grid points) somewhere on the line.
    """
    _check_speed_rate(speed, rate_hz)
    for name, v in (
        ("max_linear_speed_m_s", max_linear_speed_m_s),
        ("max_linear_acceleration_m_s2", max_linear_acceleration_m_s2),
        ("max_angular_speed_rad_s", max_angular_speed_rad_s),
        ("max_angular_acceleration_rad_s2", max_angular_acceleration_rad_s2),
        ("path_step_m", path_step_m),
        ("path_step_rad", path_step_rad),
        ("max_joint_step_rad", max_joint_step_rad),
    ):
        if not (v > 0.0) or not math.isfinite(v):
            raise ValueError(f"{name} must be positive and finite, got {v!r}")
    qs = check_joints(np.asarray(q_start, dtype=np.float64).reshape(5), model)
    goal = check_pose(pose_goal)
    p0 = fk(qs, model)
    phi0 = float(qs[1] + qs[2] + qs[3])
    # Signed distance along the arm plane (eq. 20): negative on a reach-over configuration.
    r0 = float(p0[0] * math.cos(qs[0]) + p0[1] * math.sin(qs[0]))
    roll0 = float(qs[4]) if r0 >= 0.0 else float(qs[4]) - math.pi
    try:
        qg = ik(goal, roll=roll0 if roll is None else float(roll), seed=qs, model=model)
    except Unreachable as e:
        raise _located(e, "the goal of the Cartesian line is unreachable") from None
    # Joint-space approach angle and roll at both ends: interpolating these keeps the
    # ranges' own continuity (no wrap through an excluded angle).
    phi1 = float(qg[1] + qg[2] + qg[3])
    P0, P1 = p0[:3], np.array(goal[:3])
    length = float(np.linalg.norm(P1 - P0))
    dphi, droll = phi1 - phi0, float(qg[4] - qs[4])
    n_dense = 1 + max(
        2,
        math.ceil(length / path_step_m),
        math.ceil(abs(dphi) / path_step_rad),
        math.ceil(abs(droll) / path_step_rad),
    )
    if n_dense > _MAX_DENSE:
        raise ValueError(
            f"path_step_m/path_step_rad give {n_dense} grid points (limit {_MAX_DENSE}); "
            "use larger steps"
        )
    if length < 1e-12 and abs(dphi) < 1e-12 and abs(droll) < 1e-12:
        z = np.zeros((1, 5))
        return JointTrajectory(np.zeros(1), qs[None, :], z, z)

    def poses_at(s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        pos = P0[None, :] + s[:, None] * (P1 - P0)[None, :]
        phi = phi0 + s * dphi
        # The chapter's (u, w) is measured radially outwards: flip for a reach-over start.
        sign = 1.0 if r0 >= 0.0 else -1.0
        poses = np.column_stack([pos, sign * np.cos(phi), np.sin(phi)])
        return poses, roll0 + s * droll

    def solve(s: np.ndarray) -> np.ndarray:
        poses, rolls = poses_at(s)
        q, ok, br = ik_batch_branches(poses, rolls, seed=qs, model=model)
        if not ok.all():
            i = int(np.argmin(ok))
            where = (
                f"Cartesian line blocked at {100 * s[i]:.1f} % of the path, at "
                f"(x, y, z) = ({poses[i, 0]:.4f}, {poses[i, 1]:.4f}, {poses[i, 2]:.4f}) m"
            )
            try:
                ik(poses[i], roll=rolls[i], seed=qs, model=model)
            except Unreachable as e:
                raise _located(e, where) from None
            raise Unreachable(where)  # pragma: no cover - batch and scalar agree
        changed = np.flatnonzero(br != br[0])
        if changed.size:
            i = int(changed[0])
            raise Unreachable(
                f"Cartesian line changes IK branch at {100 * s[i]:.1f} % of the path: from "
                f"{BRANCHES[br[0]]} to {BRANCHES[br[i]]} at (x, y, z) = "
                f"({poses[i, 0]:.4f}, {poses[i, 1]:.4f}, {poses[i, 2]:.4f}) m"
            )
        return q

    s_d = np.linspace(0.0, 1.0, n_dense)
    q_d = solve(s_d)
    steps = np.abs(np.diff(np.vstack([qs, q_d]), axis=0))
    if steps.max() > max_joint_step_rad:
        i, j = np.unravel_index(int(np.argmax(steps)), steps.shape)
        where = s_d[max(int(i) - 1, 0)]
        raise Unreachable(
            f"Cartesian line is not continuous in joint space at {100 * where:.1f} % of the "
            f"path: q{j + 1} jumps by {steps[i, j]:.3f} rad between neighbouring points "
            f"(limit {max_joint_step_rad} rad); the line passes through or near a singular "
            "configuration (wrist over the column) or a wrap of a joint range"
        )
    dq = np.gradient(q_d, s_d, axis=0, edge_order=2)
    ddq = np.gradient(dq, s_d, axis=0, edge_order=2)

    vmax = model.max_velocity_rad_s * speed
    amax = model.max_acceleration_rad_s2 * speed * speed
    # Duration from the Cartesian and angular limits (quintic peaks) ...
    T = 0.0
    for dist, v, a in (
        (length, max_linear_speed_m_s, max_linear_acceleration_m_s2),
        (abs(dphi), max_angular_speed_rad_s, max_angular_acceleration_rad_s2),
        (abs(droll), max_angular_speed_rad_s, max_angular_acceleration_rad_s2),
    ):
        T = max(
            T,
            QUINTIC_PEAK_VELOCITY * dist / (v * speed),
            math.sqrt(QUINTIC_PEAK_ACCELERATION * dist / (a * speed * speed)),
        )
    # ... and from the joint limits: qd = q'(s) s'(tau) / T, qdd = (q'' s'^2 + q' s'') / T^2.
    tau = np.linspace(0.0, 1.0, 4001)
    s_t, sd_t, sdd_t = quintic(tau)
    d1 = _interp_rows(s_t, s_d, dq)
    d2 = _interp_rows(s_t, s_d, ddq)
    V = np.abs(d1 * sd_t[:, None]).max(axis=0)
    A = np.abs(d2 * (sd_t**2)[:, None] + d1 * sdd_t[:, None]).max(axis=0)
    T = max(T, float(np.max(V / vmax)), math.sqrt(float(np.max(A / amax))), 1e-3)
    T *= 1.0 + 1e-6
    for _ in range(5):
        n = check_plan_size(T, rate_hz)
        t = np.linspace(0.0, T, n)
        s_o, sd_o, sdd_o = quintic(t / T)
        q = solve(s_o)
        q[0] = qs
        d1o = _interp_rows(s_o, s_d, dq)
        d2o = _interp_rows(s_o, s_d, ddq)
        qd = d1o * (sd_o / T)[:, None]
        qdd = (d2o * (sd_o**2)[:, None] + d1o * sdd_o[:, None]) / (T * T)
        qd[0] = qd[-1] = 0.0
        qdd[0] = qdd[-1] = 0.0
        over = max(float(np.max(np.abs(qd) / vmax)), math.sqrt(float(np.max(np.abs(qdd) / amax))))
        if over <= 1.0:
            break
        T *= over * (1.0 + 1e-6)
    return JointTrajectory(t, check_joints(q, model), qd, qdd)


def _interp_rows(x: np.ndarray, xp: np.ndarray, fp: np.ndarray) -> np.ndarray:
    """Per-column linear interpolation of ``fp`` (M, 5) sampled at ``xp`` onto ``x``."""
    return np.stack([np.interp(x, xp, fp[:, j]) for j in range(fp.shape[1])], axis=-1)
