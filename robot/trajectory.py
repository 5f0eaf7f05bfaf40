"""Joint-space trajectories: synchronised moves under per-joint speed and acceleration limits.

A :class:`JointTrajectory` is a time-stamped table of joint positions and velocities that a
driver plays back.  :func:`plan_joint_move` builds the classic synchronised trapezoidal
velocity profile: each joint's time-optimal trapezoid is computed, the slowest joint sets the
duration, and every joint is rescaled to finish together (so the path is a straight line in
joint space).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robot.model import ASEA, ArmModel, check_joints

__all__ = ["JointTrajectory", "plan_joint_move"]


@dataclass(frozen=True)
class JointTrajectory:
    """A sampled joint trajectory.

    Attributes
    ----------
    t_s : ndarray of shape (M,)
        Sample times in seconds from the start, strictly increasing, ``t_s[0] == 0``.
    q : ndarray of shape (M, 5)
        Joint positions, radians.
    qd : ndarray of shape (M, 5)
        Joint velocities, rad/s.
    """

    t_s: NDArray[np.float64]
    q: NDArray[np.float64]
    qd: NDArray[np.float64]

    def __post_init__(self) -> None:
        t, q, qd = (np.asarray(a, dtype=np.float64) for a in (self.t_s, self.q, self.qd))
        if t.ndim != 1 or t.size < 1:
            raise ValueError(f"t_s must be a non-empty 1-D array, got shape {t.shape}")
        if q.shape != (t.size, 5) or qd.shape != (t.size, 5):
            raise ValueError(
                f"q and qd must have shape ({t.size}, 5), got {q.shape} and {qd.shape}"
            )
        if t.size > 1 and not np.all(np.diff(t) > 0):
            raise ValueError("t_s must be strictly increasing")
        for name, a in (("t_s", t), ("q", q), ("qd", qd)):
            a.setflags(write=False)
            object.__setattr__(self, name, a)

    @property
    def duration_s(self) -> float:
        """Duration of the move in seconds."""
        return float(self.t_s[-1])

    @property
    def start(self) -> NDArray[np.float64]:
        """First configuration, shape (5,)."""
        return self.q[0]

    @property
    def goal(self) -> NDArray[np.float64]:
        """Last configuration, shape (5,)."""
        return self.q[-1]

    def sample(self, t: float | ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Linearly interpolate ``(q, qd)`` at time(s) ``t``, clamped to the ends."""
        ta = np.clip(np.asarray(t, dtype=np.float64), 0.0, self.duration_s)
        if self.t_s.size == 1:
            shape = (*ta.shape, 5)
            return np.broadcast_to(self.q[0], shape).copy(), np.zeros(shape)
        q = np.stack([np.interp(ta, self.t_s, self.q[:, j]) for j in range(5)], axis=-1)
        qd = np.stack([np.interp(ta, self.t_s, self.qd[:, j]) for j in range(5)], axis=-1)
        return q, qd


def plan_joint_move(
    q_start: ArrayLike,
    q_goal: ArrayLike,
    *,
    speed: float = 1.0,
    rate_hz: float = 100.0,
    model: ArmModel = ASEA,
) -> JointTrajectory:
    """Synchronised trapezoidal joint move from ``q_start`` to ``q_goal``.

    Parameters
    ----------
    q_start, q_goal : array_like of shape (5,)
        Start and goal configurations, radians; both are checked against the joint limits.
    speed : float in (0, 1]
        Fraction of the model's velocity limits (accelerations scale with ``speed**2`` so
        the profile keeps its shape).
    rate_hz : float
        Sampling rate of the returned table.
    model : ArmModel
        Supplies the joint ranges and the velocity and acceleration limits.

    Returns
    -------
    JointTrajectory
        Samples at ``rate_hz`` plus the exact end point.

    Raises
    ------
    ValueError
        ``speed`` outside (0, 1] or ``rate_hz`` not positive.
    JointLimitError
        Either end lies outside the joint ranges (a straight line in joint space between two
        in-range configurations stays in range, the ranges being boxes).
    """
    if not (0.0 < speed <= 1.0) or not np.isfinite(speed):
        raise ValueError(f"speed must be in (0, 1], got {speed!r}")
    if not (rate_hz > 0.0) or not np.isfinite(rate_hz):
        raise ValueError(f"rate_hz must be positive, got {rate_hz!r}")
    qs = check_joints(np.asarray(q_start, dtype=np.float64).reshape(5), model)
    qg = check_joints(np.asarray(q_goal, dtype=np.float64).reshape(5), model)
    dq = qg - qs
    dist = np.abs(dq)
    vmax = model.max_velocity_rad_s * speed
    amax = model.max_acceleration_rad_s2 * speed * speed
    if not np.any(dist > 1e-12):
        return JointTrajectory(np.zeros(1), qs[None, :], np.zeros((1, 5)))
    # Per-joint minimum duration of a trapezoid (or triangle when vmax is never reached).
    tri = dist < vmax**2 / amax
    t_joint = np.where(tri, 2.0 * np.sqrt(dist / amax), dist / vmax + vmax / amax)
    T, tb = _common_profile(dist, vmax, amax, float(t_joint.max()))
    v = dist / (T - tb)
    a = v / tb
    n = max(2, int(np.ceil(T * rate_hz)) + 1)
    t = np.linspace(0.0, T, n)
    tt = t[:, None]
    s = np.where(
        tt < tb,
        0.5 * a * tt**2,
        np.where(tt <= T - tb, a * tb * (tt - 0.5 * tb), dist - 0.5 * a * (T - tt) ** 2),
    )
    sd = np.where(tt < tb, a * tt, np.where(tt <= T - tb, v, a * (T - tt)))
    sign = np.sign(dq)
    q = qs + sign * s
    q[-1] = qg
    qd = sign * sd
    qd[-1] = 0.0
    return JointTrajectory(t, q, qd)


def _common_profile(
    dist: NDArray[np.float64], vmax: NDArray[np.float64], amax: NDArray[np.float64], T0: float
) -> tuple[float, float]:
    """Shortest common duration ``T`` and blend time ``tb`` that keep every joint in limits.

    With a shared trapezoid (accelerate for ``tb``, cruise, decelerate for ``tb``) joint j
    needs ``v_j = d_j / (T - tb) <= vmax_j`` and ``a_j = v_j / tb <= amax_j``, i.e.
    ``tb (T - tb) >= d_j / amax_j``.  For a given ``T`` the smallest admissible ``tb`` is the
    largest root of the acceleration conditions; ``T`` grows from the slowest joint's own
    time-optimal duration ``T0`` until the speed conditions hold too.
    """
    T = T0
    for _ in range(200):
        disc = T * T - 4.0 * dist / amax
        if np.all(disc >= 0.0):
            tb = float(np.max((T - np.sqrt(np.maximum(disc, 0.0))) / 2.0))
            tb = min(max(tb, 1e-9), T / 2.0)
            if np.all(dist <= vmax * (T - tb) * (1.0 + 1e-12)):
                return T, tb
        T *= 1.002
    raise AssertionError("no synchronised profile found")  # unreachable for finite inputs
