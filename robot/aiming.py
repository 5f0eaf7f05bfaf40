"""Aiming the arm at a point: the one geometry shared by every view planner.

A 5-DOF arm (chapter eq. 20) points its approach axis only within the vertical plane
through the column and the flange, so a view of a point ``P`` is named in the arm's own
terms: the approach angle ``phi = q2 + q3 + q4`` from the horizontal (``-pi/2`` straight
down, ``-pi/3`` tilted 30 deg with the flange on the column's side of ``P``, ``-2 pi / 3``
tilted 30 deg from beyond ``P``), the distance along the axis and the roll ``q5``.

* :func:`approach_axis` is eq. 20's approach direction ``(u cos(theta), u sin(theta), w)``
  with ``(u, w) = (cos phi, sin phi)``;
* :func:`aimed_flange_pose` puts the flange ``distance_m`` back along that axis from the
  aim point, with ``theta`` the aim point's azimuth, so the flange's approach axis passes
  through the aim point (used by the calibration planner and the simulator's named poses);
* :func:`look_at` aims the *camera's* optical axis at ``P`` instead, for a camera mounted
  off the approach axis (``T_ee_cam``, the hand-eye result): it corrects the flange's aim
  point, distance and approach angle by fixed-point iteration until the optical axis passes
  through ``P`` at the requested distance with the requested elevation (used by the
  inspection's viewpoint planner).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robot.errors import Unreachable
from robot.kinematics import T_base_ee, ik
from robot.model import ASEA, ArmModel

__all__ = ["AimedCamera", "aimed_flange_pose", "approach_axis", "axis_angles", "look_at"]


def approach_axis(azimuth_rad: float, phi_rad: float) -> NDArray[np.float64]:
    """Unit approach direction of eq. 20 in the arm plane at ``azimuth_rad``, shape (3,).

    ``phi_rad`` is measured from the horizontal, positive upwards; its horizontal part
    points radially outwards for ``|phi| < pi / 2``.
    """
    return np.array(
        [
            math.cos(azimuth_rad) * math.cos(phi_rad),
            math.sin(azimuth_rad) * math.cos(phi_rad),
            math.sin(phi_rad),
        ]
    )


def aimed_flange_pose(
    aim: ArrayLike, *, phi_rad: float, distance_m: float
) -> tuple[float, float, float, float, float]:
    """Chapter pose ``(x, y, z, u, w)`` whose approach axis passes through ``aim``.

    Parameters
    ----------
    aim : array_like of shape (3,)
        Point the approach axis goes through, base frame, metres.
    phi_rad : float
        Approach angle from the horizontal (eq. 20's ``q2 + q3 + q4``).
    distance_m : float
        Distance from the flange to ``aim`` along the axis.

    Returns
    -------
    tuple of 5 floats
        Flange position ``aim - distance_m * approach_axis(atan2(y, x), phi)`` and
        ``(u, w) = (cos phi, sin phi)``, ready for :func:`robot.kinematics.ik`.
    """
    a = np.asarray(aim, dtype=np.float64)
    az = math.atan2(a[1], a[0])
    p = a - distance_m * approach_axis(az, phi_rad)
    return (float(p[0]), float(p[1]), float(p[2]), math.cos(phi_rad), math.sin(phi_rad))


def axis_angles(direction: ArrayLike) -> tuple[float, float]:
    """Tilt from the downward vertical and azimuth of a direction, radians.

    ``tilt = 0`` is straight down; the azimuth is that of the horizontal part (0 when the
    direction is vertical).
    """
    d = np.asarray(direction, dtype=np.float64)
    d = d / np.linalg.norm(d)
    tilt = math.acos(max(-1.0, min(1.0, -float(d[2]))))
    h = math.hypot(float(d[0]), float(d[1]))
    az = math.atan2(float(d[1]), float(d[0])) if h > 1e-12 else 0.0
    return tilt, az


@dataclass(frozen=True)
class AimedCamera:
    """The arm configuration whose camera looks at a point.

    Attributes
    ----------
    q : ndarray of shape (5,)
        Joints within the ranges, radians.
    T_base_ee : ndarray of shape (4, 4)
        Flange pose (forward kinematics of ``q``).
    T_base_cam : ndarray of shape (4, 4)
        Camera pose ``T_base_ee @ T_ee_cam`` (OpenCV camera frame, +z along the optical axis).
    miss_m : float
        Distance of the target from the optical axis (below the tolerance).
    distance_m : float
        Distance from the camera centre to the target along the optical axis.
    """

    q: NDArray[np.float64]
    T_base_ee: NDArray[np.float64]
    T_base_cam: NDArray[np.float64]
    miss_m: float
    distance_m: float


def look_at(
    target: ArrayLike,
    *,
    phi_rad: float,
    distance_m: float,
    T_ee_cam: ArrayLike,
    roll_rad: float = 0.0,
    seed: ArrayLike | None = None,
    tol_m: float = 1e-6,
    max_iter: int = 30,
    model: ArmModel = ASEA,
) -> AimedCamera:
    """Joints that put ``target`` on the camera's optical axis, ``distance_m`` in front of it.

    The optical axis ``z_cam`` is brought to the elevation ``phi_rad`` (from the horizontal,
    in the arm plane, as eq. 20's approach angle); its azimuth follows from the arm (the
    approach axis stays in the column's plane, so only the camera's offset from that axis
    turns the view sideways).  Each iteration solves the flange with the closed-form IK
    (:func:`robot.kinematics.ik`, joint ranges enforced), then moves the flange's aim point
    by the target's perpendicular offset from the optical axis, its distance by the range
    error and its approach angle by the elevation error.  With the camera on the approach
    axis (``NOMINAL_T_EE_CAM``) the first iteration is exact.

    Parameters
    ----------
    target : array_like of shape (3,)
        Point to look at, base frame, metres.
    phi_rad : float
        Elevation of the optical axis (``-pi/2``: looking straight down).
    distance_m : float
        Camera centre to ``target`` along the optical axis, metres (> 0).
    T_ee_cam : array_like of shape (4, 4)
        Camera mounting on the flange.
    roll_rad : float
        Roll q5 of the flange about its approach axis.
    seed : array_like of shape (5,), optional
        IK seed (the branch nearest to it is used); default ``model.q_ready``.
    tol_m : float
        Convergence tolerance on the miss distance and on the range.
    max_iter : int
        Iterations before giving up.
    model : ArmModel

    Returns
    -------
    AimedCamera

    Raises
    ------
    Unreachable
        The IK has no solution within the joint ranges for an iterate (the subclass says
        why), or the iteration does not converge.
    ValueError
        Non-finite inputs or a non-positive distance.
    """
    P = np.asarray(target, dtype=np.float64).reshape(-1)
    Tec = np.asarray(T_ee_cam, dtype=np.float64)
    if P.shape != (3,) or not np.isfinite(P).all():
        raise ValueError(f"target must be 3 finite numbers, got {np.asarray(target).tolist()}")
    if Tec.shape != (4, 4) or not np.isfinite(Tec).all():
        raise ValueError(f"T_ee_cam must be a finite 4x4 matrix, got shape {Tec.shape}")
    if not (math.isfinite(distance_m) and distance_m > 0.0):
        raise ValueError(f"distance_m must be positive and finite, got {distance_m!r}")
    if not (math.isfinite(phi_rad) and math.isfinite(roll_rad)):
        raise ValueError(f"phi_rad and roll_rad must be finite, got {phi_rad!r}, {roll_rad!r}")
    q_seed = np.asarray(model.q_ready if seed is None else seed, dtype=np.float64)
    aim = P.copy()
    phi_f = float(phi_rad)
    d_f = float(distance_m) + float(Tec[2, 3])  # the camera sits past the flange
    for _ in range(int(max_iter)):
        q = ik(
            aimed_flange_pose(aim, phi_rad=phi_f, distance_m=d_f),
            roll=roll_rad,
            seed=q_seed,
            model=model,
        )
        T_be = T_base_ee(q, model)
        T_bc = T_be @ Tec
        C, z = T_bc[:3, 3], T_bc[:3, 2]
        v = P - C
        along = float(v @ z)
        perp = v - along * z
        # Elevation of the optical axis in the arm plane (same sign convention as phi).
        h = float(z[0] * math.cos(q[0]) + z[1] * math.sin(q[0]))
        dphi = math.remainder(float(phi_rad) - math.atan2(float(z[2]), h), 2.0 * math.pi)
        miss = float(np.linalg.norm(perp))
        if miss < tol_m and abs(along - distance_m) < tol_m and abs(dphi) < 1e-9:
            return AimedCamera(q, T_be, T_bc, miss, along)
        aim = aim + perp
        d_f += float(distance_m) - along
        phi_f += dphi
        q_seed = q
    raise Unreachable(
        f"the camera cannot be aimed at {np.round(P, 4).tolist()} m from {distance_m:.3f} m "
        f"at phi = {math.degrees(phi_rad):.1f} deg: the aim did not converge in {max_iter} "
        f"iterations (miss {miss * 1e3:.3g} mm)"
    )
