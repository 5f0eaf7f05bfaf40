"""The ASEA 5-DOF arm: the one source of truth for its geometry, ranges and named poses.

Link lengths are those of chapter Table 1 (converted from millimetres to metres here, where
they are defined).  Joint ranges keep the Table 1 spans (360, 82.5, 63, 208.5, 331.5 deg)
with the centres fixed in ``ARCHITECTURE.md``, chosen so that a top view and two side views
of the inspection station near r = 0.8 m, z = 0.55 m are reachable.  The simulator, the 3D
view, the drivers and inverse kinematics all read :data:`ASEA`.

Joint conventions (chapter eq. 20): q1 rotates the column about the base z axis; q2, q3, q4
are pitch joints about a horizontal axis perpendicular to the arm plane, q2 measured from
the horizontal, q3 and q4 relative to the previous link; q5 rolls the flange about the
approach axis.  The approach direction makes the angle ``phi = q2 + q3 + q4`` with the
horizontal, so ``u = cos(phi)`` and ``w = sin(phi)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robot.errors import JointLimitError

__all__ = ["ASEA", "ArmModel", "check_joints"]

_DEG = math.pi / 180.0


@dataclass(frozen=True)
class ArmModel:
    """Geometry and limits of a 5-DOF ASEA-type arm (SI units, radians).

    Attributes
    ----------
    name : str
        Human-readable model name.
    link_lengths_m : tuple of 5 floats
        L1..L5 in metres: L1 base-to-shoulder height, L2 upper arm, L3 forearm,
        L4 wrist, L5 flange (chapter Table 1).
    joint_limits_rad : ndarray of shape (5, 2)
        ``[low, high]`` per joint, radians.
    max_velocity_rad_s : ndarray of shape (5,)
        Per-joint speed limit at ``speed = 1``.
    max_acceleration_rad_s2 : ndarray of shape (5,)
        Per-joint acceleration limit at ``speed = 1``.
    q_home, q_ready : ndarray of shape (5,)
        Named configurations: ``q_home`` is the parked pose (upper arm vertical, forearm
        horizontal, tool horizontal); ``q_ready`` puts the flange 0.45 m above the
        inspection station, tool pointing straight down (the top viewpoint).
    """

    name: str
    link_lengths_m: tuple[float, float, float, float, float]
    joint_limits_rad: NDArray[np.float64]
    max_velocity_rad_s: NDArray[np.float64]
    max_acceleration_rad_s2: NDArray[np.float64]
    q_home: NDArray[np.float64]
    q_ready: NDArray[np.float64]
    joint_names: tuple[str, ...] = field(default=("q1", "q2", "q3", "q4", "q5"))

    @property
    def L1(self) -> float:
        """Base-to-shoulder height L1, metres."""
        return self.link_lengths_m[0]

    @property
    def L2(self) -> float:
        """Upper-arm length L2, metres."""
        return self.link_lengths_m[1]

    @property
    def L3(self) -> float:
        """Forearm length L3, metres."""
        return self.link_lengths_m[2]

    @property
    def L45(self) -> float:
        """Wrist plus flange length L4 + L5 (collinear in eq. 20), metres."""
        return self.link_lengths_m[3] + self.link_lengths_m[4]

    @property
    def lower(self) -> NDArray[np.float64]:
        """Lower joint limits, radians, shape (5,)."""
        return self.joint_limits_rad[:, 0]

    @property
    def upper(self) -> NDArray[np.float64]:
        """Upper joint limits, radians, shape (5,)."""
        return self.joint_limits_rad[:, 1]

    def within_limits(self, q: ArrayLike, *, tol_rad: float = 1e-9) -> NDArray[np.bool_]:
        """True where every joint of ``q`` (shape (5,) or (N, 5)) lies within its range."""
        qa = np.asarray(q, dtype=np.float64)
        ok = (qa >= self.lower - tol_rad) & (qa <= self.upper + tol_rad)
        return np.all(ok, axis=-1)


def _rad(deg: tuple[float, ...]) -> NDArray[np.float64]:
    arr = np.array(deg, dtype=np.float64) * _DEG
    arr.setflags(write=False)
    return arr


ASEA = ArmModel(
    name="ASEA IRB-type 5-DOF arm (chapter Table 1)",
    # Table 1: L1..L5 = 730, 690, 670, 73, 20 mm.
    link_lengths_m=(0.730, 0.690, 0.670, 0.073, 0.020),
    # Table 1 spans 360, 82.5, 63, 208.5, 331.5 deg; centres from ARCHITECTURE.md.
    joint_limits_rad=np.array(
        [
            [-180.0, 180.0],
            [30.0, 112.5],
            [-126.0, -63.0],
            [-150.0, 58.5],
            [-165.75, 165.75],
        ]
    )
    * _DEG,
    # The chapter gives no speeds.  These are plausible for an ASEA IRB 6-class arm
    # (base axis about 95 deg/s, arm axes somewhat slower, wrist faster) and are derated so
    # that the camera is not shaken at the viewpoints; deg/s and deg/s^2.
    max_velocity_rad_s=_rad((90.0, 75.0, 75.0, 120.0, 180.0)),
    max_acceleration_rad_s2=_rad((180.0, 150.0, 150.0, 300.0, 400.0)),
    q_home=_rad((0.0, 90.0, -90.0, 0.0, 0.0)),
    # Flange at x = 0.80 m, y = 0, z = 1.00 m, tool pointing down (phi = -90 deg), elbow up;
    # solved from eq. 20 and checked by tests/robot/test_model.py.
    q_ready=np.array([0.0, 1.277232017702696, -1.7372912846625987, -1.1107370598349937, 0.0]),
)
ASEA.joint_limits_rad.setflags(write=False)
ASEA.q_ready.setflags(write=False)


def check_joints(
    q: ArrayLike, model: ArmModel = ASEA, *, tol_rad: float = 1e-9
) -> NDArray[np.float64]:
    """Validate joint values against the model's ranges; the single joint-limit gate.

    Every command path to a driver passes through this function.

    Parameters
    ----------
    q : array_like of shape (5,) or (N, 5)
        Joint values in radians.
    model : ArmModel
        The arm whose ranges apply.
    tol_rad : float
        Numerical tolerance at the range ends.

    Returns
    -------
    ndarray of float64 with the shape of ``q``.

    Raises
    ------
    ValueError
        If ``q`` has the wrong shape or contains NaN or infinity.
    JointLimitError
        Naming the first joint (1-based), its value and its range.
    """
    qa = np.asarray(q, dtype=np.float64)
    if qa.shape[-1:] != (5,) or qa.ndim not in (1, 2):
        raise ValueError(f"q must have shape (5,) or (N, 5), got {qa.shape}")
    if not np.all(np.isfinite(qa)):
        raise ValueError(f"q contains NaN or infinity: {qa.tolist()}")
    rows = qa.reshape(-1, 5)
    bad = (rows < model.lower - tol_rad) | (rows > model.upper + tol_rad)
    if bad.any():
        i, j = np.argwhere(bad)[0]
        raise JointLimitError(
            int(j) + 1, float(rows[i, j]), (float(model.lower[j]), float(model.upper[j]))
        )
    return qa
