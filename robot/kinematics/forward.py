"""Forward kinematics of the ASEA arm (chapter eq. 20) and the full flange pose.

Frames (``ARCHITECTURE.md``): ``base`` has z up with the column on its z axis; ``ee`` is the
flange after joint 5, with its z axis along the approach direction (the direction of L4 + L5)
and q5 rolling about it.  With ``phi = q2 + q3 + q4``

    R_base_ee = Rz(q1) @ Ry(pi/2 - phi) @ Rz(q5)

so that ``z_ee = (cos q1 cos phi, sin q1 cos phi, sin phi)`` agrees with eq. 20's
``(u, w) = (cos phi, sin phi)``.  With the tool pointing straight down (phi = -pi/2) and
q1 = q5 = 0, ``x_ee`` points back towards the column (-x of base) and ``y_ee`` along +y.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robot.model import ASEA, ArmModel

__all__ = ["MAX_ABS_JOINT_RAD", "R_base_ee", "T_base_ee", "check_q", "fk", "joint_positions"]

#: Largest joint magnitude the kinematics accepts, radians (two turns either way): beyond
#: it a value is a unit mistake, and ``cos``/``sin`` of huge arguments lose every digit.
MAX_ABS_JOINT_RAD = 4.0 * np.pi


def _has_bool(q: object) -> bool:
    if isinstance(q, bool | np.bool_):
        return True
    if isinstance(q, list | tuple):
        return any(_has_bool(v) for v in q)
    return False


def check_q(q: ArrayLike) -> NDArray[np.float64]:
    """Return ``q`` as float64 of shape (5,) or (N, 5), finite and within
    :data:`MAX_ABS_JOINT_RAD`, or raise ``ValueError`` quoting the shape or the values.

    Booleans are not joint values: a boolean array, or a list holding one, is refused.
    """
    if _has_bool(q) or (isinstance(q, np.ndarray) and q.dtype == np.bool_):
        raise ValueError(f"q must hold numbers (radians), not booleans, got {q!r}")
    try:
        qa = np.asarray(q, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"q must be numbers of shape (5,) or (N, 5), got {q!r}") from None
    if qa.ndim not in (1, 2) or qa.shape[-1] != 5:
        raise ValueError(f"q must have shape (5,) or (N, 5), got {qa.shape}")
    bad = ~(np.abs(qa) <= MAX_ABS_JOINT_RAD)  # also catches NaN
    if bad.any():
        vals = qa[bad][:5].tolist()
        raise ValueError(
            f"q must be finite with |q| <= {MAX_ABS_JOINT_RAD:.6g} rad (two turns), got {vals}"
        )
    return qa


def fk(q: ArrayLike, model: ArmModel = ASEA) -> NDArray[np.float64]:
    """Chapter eq. 20: the flange position and approach direction ``(x, y, z, u, w)``.

    Parameters
    ----------
    q : array_like of shape (5,) or (N, 5)
        Joint values, radians.
    model : ArmModel
        Link lengths L1..L5 (metres).

    Returns
    -------
    ndarray of shape (5,) or (N, 5)
        ``x, y, z`` in metres and ``u = cos(q2+q3+q4)``, ``w = sin(q2+q3+q4)``.

    Examples
    --------
    >>> import numpy as np
    >>> from robot.model import ASEA
    >>> np.round(fk(ASEA.q_home), 3)
    array([0.763, 0.   , 1.42 , 1.   , 0.   ])
    """
    qa = check_q(q)
    q1, q2, q3, q4 = qa[..., 0], qa[..., 1], qa[..., 2], qa[..., 3]
    L1, L2, L3, L45 = model.L1, model.L2, model.L3, model.L45
    a23 = q2 + q3
    phi = a23 + q4
    r = L2 * np.cos(q2) + L3 * np.cos(a23) + L45 * np.cos(phi)
    out = np.empty(qa.shape, dtype=np.float64)
    out[..., 0] = np.cos(q1) * r
    out[..., 1] = np.sin(q1) * r
    out[..., 2] = L2 * np.sin(q2) + L3 * np.sin(a23) + L1 + L45 * np.sin(phi)
    out[..., 3] = np.cos(phi)
    out[..., 4] = np.sin(phi)
    return out


def R_base_ee(q: ArrayLike) -> NDArray[np.float64]:
    """Rotation of the flange in the base frame, shape (3, 3) or (N, 3, 3) (see module doc)."""
    qa = check_q(q)
    q1, q5 = qa[..., 0], qa[..., 4]
    phi = qa[..., 1] + qa[..., 2] + qa[..., 3]
    c1, s1 = np.cos(q1), np.sin(q1)
    cp, sp = np.cos(phi), np.sin(phi)  # Ry(pi/2 - phi) has cos = sin(phi), sin = cos(phi)
    c5, s5 = np.cos(q5), np.sin(q5)
    # Columns of Rz(q1) @ Ry(pi/2 - phi): x' = (c1 sp, s1 sp, -cp), y' = (-s1, c1, 0),
    # z' = (c1 cp, s1 cp, sp).  Then roll q5 about z'.
    xa = np.stack([c1 * sp, s1 * sp, -cp], axis=-1)
    ya = np.stack([-s1, c1, np.zeros_like(q1)], axis=-1)
    za = np.stack([c1 * cp, s1 * cp, sp], axis=-1)
    x = c5[..., None] * xa + s5[..., None] * ya
    y = -s5[..., None] * xa + c5[..., None] * ya
    return np.stack([x, y, za], axis=-1)


def T_base_ee(q: ArrayLike, model: ArmModel = ASEA) -> NDArray[np.float64]:
    """Full pose of the flange, 4x4 (or (N, 4, 4)), position from eq. 20, roll q5 included."""
    qa = check_q(q)
    p = fk(qa, model)[..., :3]
    T = np.zeros((*qa.shape[:-1], 4, 4), dtype=np.float64)
    T[..., :3, :3] = R_base_ee(qa)
    T[..., :3, 3] = p
    T[..., 3, 3] = 1.0
    return T


def joint_positions(q: ArrayLike, model: ArmModel = ASEA) -> NDArray[np.float64]:
    """Points of the kinematic chain for drawing, shape (5, 3) or (N, 5, 3).

    Rows: base (origin), shoulder (top of L1, axis of q2), elbow (q3), wrist (q4), flange.
    """
    qa = check_q(q)
    q1, q2, q3, q4 = qa[..., 0], qa[..., 1], qa[..., 2], qa[..., 3]
    a23 = q2 + q3
    phi = a23 + q4
    r = np.stack(
        [
            np.zeros_like(q1),
            np.zeros_like(q1),
            model.L2 * np.cos(q2),
            model.L2 * np.cos(q2) + model.L3 * np.cos(a23),
            model.L2 * np.cos(q2) + model.L3 * np.cos(a23) + model.L45 * np.cos(phi),
        ],
        axis=-1,
    )
    z = np.stack(
        [
            np.zeros_like(q1),
            np.full_like(q1, model.L1),
            model.L1 + model.L2 * np.sin(q2),
            model.L1 + model.L2 * np.sin(q2) + model.L3 * np.sin(a23),
            model.L1 + model.L2 * np.sin(q2) + model.L3 * np.sin(a23) + model.L45 * np.sin(phi),
        ],
        axis=-1,
    )
    return np.stack([np.cos(q1)[..., None] * r, np.sin(q1)[..., None] * r, z], axis=-1)
