"""Inverse kinematics for a full 6-DOF flange pose on the 5-DOF ASEA arm.

A 5-DOF arm reaches a position ``p`` only with its approach axis ``a = z_ee`` in the vertical
plane through the base z axis and ``p`` (chapter eq. 20: ``a = (u cos q1, u sin q1, w)``);
the roll q5 about ``a`` is then free.  The reachable orientations at ``p`` are therefore

    S(p) = { R : (R e_z) . n = 0 },   n = (-sin(theta), cos(theta), 0),  theta = atan2(p_y, p_x).

Projection onto ``S(p)``: a rotation by angle ``alpha`` moves any unit vector by at most
``alpha``, so bringing ``a`` into the plane needs at least the angle between ``a`` and the
plane, ``alpha = asin(|a . n|)``.  That bound is attained by the rotation ``D`` about
``k = a x a_p / |a x a_p|`` by ``alpha``, which turns ``a`` onto its normalised projection
``a_p = (a - (a . n) n) / |a - (a . n) n|``.  Hence ``R* = D R_target`` is a closest reachable
orientation in the geodesic (rotation-angle) metric, the residual is exactly ``alpha``, and
``R_target = D^T R*``.  ``R*`` is unique unless ``a`` is normal to the plane (``alpha = pi/2``),
where the seed's approach angle ``q2 + q3 + q4`` picks the in-plane direction.

The position is kept exactly: the closest achievable pose differs from the target in
orientation only.  Joint ranges are not part of the projection: when the projected pose needs
a joint outside its range, :class:`~robot.errors.JointLimitsBlock` is raised as for
:func:`~robot.kinematics.ik`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robot.errors import OrientationNotAchievable
from robot.kinematics.analytic import _AXIS_EPS, ik
from robot.kinematics.forward import T_base_ee
from robot.model import ASEA, ArmModel

__all__ = ["DEFAULT_MAX_ORIENTATION_ERROR_RAD", "IKPoseResult", "ik_pose", "rotation_angle"]

#: Default bound on the orientation residual: 1 microradian, i.e. only targets that a 5-DOF
#: arm reaches up to rounding (poses built from its own forward kinematics and exact
#: transforms) pass.  Callers that want the closest achievable pose of an arbitrary target
#: pass a larger bound (``math.pi`` accepts any).
DEFAULT_MAX_ORIENTATION_ERROR_RAD = 1e-6
_ORTHO_TOL = 1e-6


@dataclass(frozen=True)
class IKPoseResult:
    """The closest pose a 5-DOF arm reaches to a 6-DOF target, and how close it is.

    Attributes
    ----------
    q : ndarray of shape (5,)
        Joint values within the ranges, radians.
    T_base_ee : ndarray of shape (4, 4)
        The flange pose these joints reach (forward kinematics).
    position_error_m : float
        Distance between the target and the reached flange positions (rounding only).
    orientation_error_rad : float
        Rotation angle between the target and the reached orientations.
    R_residual : ndarray of shape (3, 3)
        Rotation, in the base frame, still missing: ``R_target = R_residual @ T_base_ee[:3, :3]``.
    """

    q: NDArray[np.float64]
    T_base_ee: NDArray[np.float64]
    position_error_m: float
    orientation_error_rad: float
    R_residual: NDArray[np.float64]


def rotation_angle(R: ArrayLike) -> float:
    """Rotation angle of ``R`` in [0, pi], accurate also for tiny angles."""
    Ra = np.asarray(R, dtype=np.float64)
    v = np.array([Ra[2, 1] - Ra[1, 2], Ra[0, 2] - Ra[2, 0], Ra[1, 0] - Ra[0, 1]])
    return float(math.atan2(0.5 * np.linalg.norm(v), 0.5 * (np.trace(Ra) - 1.0)))


def _check_T(T: ArrayLike) -> NDArray[np.float64]:
    Ta = np.asarray(T, dtype=np.float64)
    if Ta.shape != (4, 4) or not np.all(np.isfinite(Ta)):
        raise ValueError(f"T_base_ee_target must be a finite 4x4 array, got shape {Ta.shape}")
    R = Ta[:3, :3]
    ortho = float(np.abs(R.T @ R - np.eye(3)).max())
    if ortho > _ORTHO_TOL or np.linalg.det(R) <= 0 or np.abs(Ta[3] - (0, 0, 0, 1)).max() > 1e-9:
        raise ValueError(
            "T_base_ee_target must be a rigid transform (orthonormal rotation with det +1, "
            f"last row 0 0 0 1); |R^T R - I| = {ortho:.3g}, last row {Ta[3].tolist()}"
        )
    return Ta


def _rotation_about(k: NDArray[np.float64], angle: float) -> NDArray[np.float64]:
    """Rodrigues: rotation by ``angle`` about the unit axis ``k``."""
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * K + (1.0 - math.cos(angle)) * (K @ K)


def ik_pose(
    T_base_ee_target: ArrayLike,
    *,
    seed: ArrayLike | None = None,
    max_orientation_error_rad: float = DEFAULT_MAX_ORIENTATION_ERROR_RAD,
    model: ArmModel = ASEA,
) -> IKPoseResult:
    """Joints reaching the closest achievable pose to a 6-DOF flange target.

    The target orientation is projected onto the orientations the arm reaches at the target
    position (module docstring), then solved with the closed form of eq. 20.

    Parameters
    ----------
    T_base_ee_target : array_like of shape (4, 4)
        Target flange pose in the base frame (``T_a_b`` convention).
    seed : array_like of shape (5,), optional
        Configuration to stay close to (see :func:`robot.kinematics.ik`); default q_home.
    max_orientation_error_rad : float
        Largest accepted rotation between the target and the reachable orientation; default
        :data:`DEFAULT_MAX_ORIENTATION_ERROR_RAD` (1e-6 rad).
    model : ArmModel
        Link lengths and joint ranges.

    Returns
    -------
    IKPoseResult

    Raises
    ------
    ValueError
        ``T_base_ee_target`` is not a finite rigid transform, or a bad tolerance or seed.
    OrientationNotAchievable
        The residual rotation exceeds ``max_orientation_error_rad`` (checked first).
    OutOfReach, JointLimitsBlock
        As :func:`robot.kinematics.ik` for the projected pose.
    """
    if not (max_orientation_error_rad >= 0.0):
        raise ValueError(
            f"max_orientation_error_rad must be >= 0, got {max_orientation_error_rad!r}"
        )
    T = _check_T(T_base_ee_target)
    p, R_t = T[:3, 3], T[:3, :3]
    a = R_t[:, 2]
    seed_q = np.asarray(model.q_home if seed is None else seed, dtype=np.float64).reshape(5)
    rho = math.hypot(p[0], p[1])
    if rho > _AXIS_EPS:
        theta = math.atan2(p[1], p[0])
    elif math.hypot(a[0], a[1]) > 1e-12:  # on the q1 axis: the plane of the approach axis
        theta = math.atan2(a[1], a[0])
    else:
        theta = float(seed_q[0])
    c, s = math.cos(theta), math.sin(theta)
    n = np.array([-s, c, 0.0])
    off = float(a @ n)
    a_p = a - off * n
    norm_p = float(np.linalg.norm(a_p))
    if norm_p < 1e-12:  # approach normal to the plane: every in-plane direction is as close
        phi_s = float(seed_q[1] + seed_q[2] + seed_q[3])
        a_p = np.array([math.cos(phi_s) * c, math.cos(phi_s) * s, math.sin(phi_s)])
        norm_p = 1.0
    a_p = a_p / norm_p
    alpha = math.atan2(abs(off), norm_p)
    if alpha > max_orientation_error_rad:
        raise OrientationNotAchievable(
            f"orientation not achievable: the approach axis is {alpha:.6g} rad "
            f"({math.degrees(alpha):.4f} deg) out of the vertical plane through the base z "
            f"axis and the flange position (azimuth {math.degrees(theta):.3f} deg), in which "
            f"a 5-DOF arm must keep it; allowed {max_orientation_error_rad:.3g} rad",
            alpha,
        )
    k = np.cross(a, a_p)
    kn = float(np.linalg.norm(k))
    R_star = _rotation_about(k / kn, alpha) @ R_t if kn > 1e-15 else R_t.copy()
    # Read phi and the roll off the projected orientation R* = Rz(theta) Ry(pi/2-phi) Rz(psi).
    horiz = float(a_p[0] * c + a_p[1] * s)
    phi = math.atan2(float(a_p[2]), horiz)
    x_axis = np.array([c * math.sin(phi), s * math.sin(phi), -math.cos(phi)])
    y_axis = np.array([-s, c, 0.0])
    psi = math.atan2(float(R_star[:, 0] @ y_axis), float(R_star[:, 0] @ x_axis))
    pose = (float(p[0]), float(p[1]), float(p[2]), math.cos(phi), math.sin(phi))
    if rho <= _AXIS_EPS:  # ik takes the arm plane from the seed's q1 on the axis
        seed_q = seed_q.copy()
        seed_q[0] = theta
    q = ik(pose, roll=psi, seed=seed_q, model=model)
    T_ach = T_base_ee(q, model)
    R_res = R_t @ T_ach[:3, :3].T
    for arr in (q, T_ach, R_res):
        arr.setflags(write=False)
    return IKPoseResult(
        q=q,
        T_base_ee=T_ach,
        position_error_m=float(np.linalg.norm(T_ach[:3, 3] - p)),
        orientation_error_rad=rotation_angle(R_res),
        R_residual=R_res,
    )
