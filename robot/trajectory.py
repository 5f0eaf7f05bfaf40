"""Trajectories for the driver: synchronised joint moves, Cartesian lines, resampling.

A :class:`JointTrajectory` is a time-stamped table of joint positions, velocities and
accelerations that a driver plays back.

* :func:`plan_joint_move` moves every joint on a straight line in joint space, synchronised
  so that all arrive together, with either the classic trapezoidal velocity profile (each
  joint's time-optimal trapezoid, the slowest sets the duration) or a quintic
  (minimum-jerk, ``s = 10 t^3 - 15 t^4 + 6 t^5``) profile with continuous acceleration.
* :func:`robot.trajectory_cartesian.plan_cartesian_line` (its own module, which builds on
  this one) moves the flange on a straight line in Cartesian space through the closed-form
  IK, checking joint ranges and branch continuity along the path and scaling time so that
  every joint stays within its speed and acceleration limits.
* :func:`sample_at_rate` resamples any trajectory at a driver's fixed rate.

Every table these functions return has passed :func:`robot.model.check_joints`, the one
joint-limit gate, and respects the size bounds :data:`MAX_DURATION_S` and
:data:`MAX_SAMPLES` (checked before any table is allocated, so no speed or rate can make
memory grow without bound); ``speed`` is at least :data:`MIN_SPEED`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robot.errors import TrajectoryTooLong
from robot.model import ASEA, ArmModel, check_joints

__all__ = [
    "MAX_DURATION_S",
    "MAX_RATE_HZ",
    "MAX_SAMPLES",
    "MIN_SPEED",
    "JointTrajectory",
    "check_plan_size",
    "plan_joint_move",
    "quintic",
    "sample_at_rate",
]

Profile = Literal["trapezoid", "quintic"]

#: Slowest speed fraction a move may ask for.  At 0.01 the longest joint move of the ASEA
#: arm (q1 across its 360 deg range, quintic profile) lasts about 750 s.
MIN_SPEED = 0.01
#: Longest trajectory any planner returns, seconds (one hour).
MAX_DURATION_S = 3600.0
#: Highest sampling rate a planner or a resampling accepts, Hz.
MAX_RATE_HZ = 2000.0
#: Most samples in one trajectory table (one hour at 100 Hz, plus the end point); a table
#: of this size holds 3 x 5 float64 columns, about 43 MB.
MAX_SAMPLES = 360_001


def check_plan_size(duration_s: float, rate_hz: float) -> int:
    """Number of samples of a plan lasting ``duration_s`` at ``rate_hz``, within the bounds.

    Called before a table is allocated.

    Returns
    -------
    int
        ``ceil(duration_s * rate_hz) + 1`` (at least 2).

    Raises
    ------
    TrajectoryTooLong
        The duration exceeds :data:`MAX_DURATION_S` (or is not finite) or the sample count
        exceeds :data:`MAX_SAMPLES`.
    """
    if not math.isfinite(duration_s) or duration_s > MAX_DURATION_S:
        raise TrajectoryTooLong(
            f"the move would last {duration_s:.6g} s, more than the {MAX_DURATION_S:g} s a "
            "trajectory may last: raise the speed or split the move",
            duration_s=float(duration_s),
            samples=-1,
        )
    n = max(2, math.ceil(duration_s * rate_hz) + 1)
    if n > MAX_SAMPLES:
        raise TrajectoryTooLong(
            f"the move would need {n} samples ({duration_s:.6g} s at {rate_hz:g} Hz), more "
            f"than the {MAX_SAMPLES} a trajectory may hold: lower the rate",
            duration_s=float(duration_s),
            samples=n,
        )
    return n


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
    qdd : ndarray of shape (M, 5), optional
        Joint accelerations, rad/s^2.  The planners fill it from their profiles; when it is
        not given it is estimated from ``qd`` by finite differences (``numpy.gradient``).
    """

    t_s: NDArray[np.float64]
    q: NDArray[np.float64]
    qd: NDArray[np.float64]
    qdd: NDArray[np.float64] | None = None

    def __post_init__(self) -> None:
        t, q, qd = (np.array(a, dtype=np.float64) for a in (self.t_s, self.q, self.qd))
        if t.ndim != 1 or t.size < 1:
            raise ValueError(f"t_s must be a non-empty 1-D array, got shape {t.shape}")
        if q.shape != (t.size, 5) or qd.shape != (t.size, 5):
            raise ValueError(
                f"q and qd must have shape ({t.size}, 5), got {q.shape} and {qd.shape}"
            )
        if t.size > 1 and not np.all(np.diff(t) > 0):
            raise ValueError("t_s must be strictly increasing")
        if t.size > MAX_SAMPLES or t[-1] - t[0] > MAX_DURATION_S:
            raise TrajectoryTooLong(
                f"a trajectory may hold {MAX_SAMPLES} samples over {MAX_DURATION_S:g} s, got "
                f"{t.size} samples over {t[-1] - t[0]:.6g} s",
                duration_s=float(t[-1] - t[0]),
                samples=int(t.size),
            )
        if self.qdd is None:
            qdd = np.gradient(qd, t, axis=0) if t.size > 1 else np.zeros((1, 5))
        else:
            qdd = np.array(self.qdd, dtype=np.float64)
            if qdd.shape != (t.size, 5):
                raise ValueError(f"qdd must have shape ({t.size}, 5), got {qdd.shape}")
        for name, a in (("t_s", t), ("q", q), ("qd", qd), ("qdd", qdd)):
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


def quintic(tau: ArrayLike) -> tuple[NDArray[np.float64], ...]:
    """Minimum-jerk time scaling ``s(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5`` on [0, 1].

    Returns ``(s, ds/dtau, d2s/dtau2)``.  Peaks: ``ds/dtau = 15/8`` at ``tau = 1/2``,
    ``|d2s/dtau2| = 10 / sqrt(3)`` at ``tau = (3 -+ sqrt(3)) / 6``; zero velocity and
    acceleration at both ends.
    """
    t = np.clip(np.asarray(tau, dtype=np.float64), 0.0, 1.0)
    t2 = t * t
    s = t2 * t * (10.0 + t * (-15.0 + 6.0 * t))
    sd = 30.0 * t2 * (1.0 - t) ** 2
    sdd = 60.0 * t * (1.0 - t) * (1.0 - 2.0 * t)
    return s, sd, sdd


QUINTIC_PEAK_VELOCITY = 15.0 / 8.0
QUINTIC_PEAK_ACCELERATION = 10.0 / math.sqrt(3.0)


def _check_speed_rate(speed: float, rate_hz: float) -> None:
    if isinstance(speed, bool) or not (MIN_SPEED <= speed <= 1.0):
        raise ValueError(f"speed must be in [{MIN_SPEED}, 1], got {speed!r}")
    if isinstance(rate_hz, bool) or not (0.0 < rate_hz <= MAX_RATE_HZ):
        raise ValueError(f"rate_hz must be in (0, {MAX_RATE_HZ:g}] Hz, got {rate_hz!r}")


def plan_joint_move(
    q_start: ArrayLike,
    q_goal: ArrayLike,
    *,
    speed: float = 1.0,
    rate_hz: float = 100.0,
    profile: Profile = "trapezoid",
    model: ArmModel = ASEA,
) -> JointTrajectory:
    """Synchronised joint move from ``q_start`` to ``q_goal`` (a straight line in joint space).

    Parameters
    ----------
    q_start, q_goal : array_like of shape (5,)
        Start and goal configurations, radians; both are checked against the joint limits.
    speed : float in [MIN_SPEED, 1]
        Fraction of the model's velocity limits (accelerations scale with ``speed**2`` so
        the profile keeps its shape).
    rate_hz : float
        Sampling rate of the returned table.
    profile : {"trapezoid", "quintic"}
        ``"trapezoid"``: the shortest synchronised trapezoidal velocity profile (acceleration
        jumps at the blends).  ``"quintic"``: minimum-jerk ``s(t/T)`` (:func:`quintic`), whose
        duration ``T = max_j max(15/8 d_j / v_j, sqrt(10/sqrt(3) d_j / a_j))`` keeps each
        joint's peak speed and acceleration within its limits; smooth acceleration, about
        15-40 % slower than the trapezoid.
    model : ArmModel
        Supplies the joint ranges and the velocity and acceleration limits.

    Returns
    -------
    JointTrajectory
        Samples at ``rate_hz`` (rounded up to divide the duration evenly) plus the exact end.

    Raises
    ------
    ValueError
        ``speed`` outside [MIN_SPEED, 1], ``rate_hz`` outside (0, MAX_RATE_HZ] or an unknown
        ``profile``.
    TrajectoryTooLong
        The move would last longer than :data:`MAX_DURATION_S` or need more than
        :data:`MAX_SAMPLES` samples (checked before the table is built).
    JointLimitError
        Either end lies outside the joint ranges (a straight line in joint space between two
        in-range configurations stays in range, the ranges being boxes).
    """
    _check_speed_rate(speed, rate_hz)
    if profile not in ("trapezoid", "quintic"):
        raise ValueError(f"profile must be 'trapezoid' or 'quintic', got {profile!r}")
    qs = check_joints(np.asarray(q_start, dtype=np.float64).reshape(5), model)
    qg = check_joints(np.asarray(q_goal, dtype=np.float64).reshape(5), model)
    dq = qg - qs
    dist = np.abs(dq)
    vmax = model.max_velocity_rad_s * speed
    amax = model.max_acceleration_rad_s2 * speed * speed
    if not np.any(dist > 1e-12):
        return JointTrajectory(np.zeros(1), qs[None, :], np.zeros((1, 5)), np.zeros((1, 5)))
    if profile == "quintic":
        T = float(
            np.max(
                np.maximum(
                    QUINTIC_PEAK_VELOCITY * dist / vmax,
                    np.sqrt(QUINTIC_PEAK_ACCELERATION * dist / amax),
                )
            )
        )
        n = check_plan_size(T, rate_hz)
        t = np.linspace(0.0, T, n)
        sq, sdq, sddq = quintic(t / T)
        q = qs + sq[:, None] * dq
        q[-1] = qg
        return JointTrajectory(t, q, sdq[:, None] * dq / T, sddq[:, None] * dq / (T * T))
    # Per-joint minimum duration of a trapezoid (or triangle when vmax is never reached).
    tri = dist < vmax**2 / amax
    t_joint = np.where(tri, 2.0 * np.sqrt(dist / amax), dist / vmax + vmax / amax)
    T0 = float(t_joint.max())
    check_plan_size(T0, rate_hz)  # the common profile is at least as long as T0
    T, tb = _common_profile(dist, vmax, amax, T0)
    v = dist / (T - tb)
    a = v / tb
    n = check_plan_size(T, rate_hz)
    t = np.linspace(0.0, T, n)
    tt = t[:, None]
    s = np.where(
        tt < tb,
        0.5 * a * tt**2,
        np.where(tt <= T - tb, a * tb * (tt - 0.5 * tb), dist - 0.5 * a * (T - tt) ** 2),
    )
    sd = np.where(tt < tb, a * tt, np.where(tt <= T - tb, v, a * (T - tt)))
    sdd = np.where(tt < tb, a, np.where(tt <= T - tb, 0.0, -a))
    sign = np.sign(dq)
    q = qs + sign * s
    q[-1] = qg
    qd = sign * sd
    qd[-1] = 0.0
    return JointTrajectory(t, q, qd, sign * sdd)


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


def sample_at_rate(traj: JointTrajectory, rate_hz: float) -> JointTrajectory:
    """Resample ``traj`` at a driver's fixed rate.

    Samples lie at ``k / rate_hz`` for ``k = 0, 1, ...`` plus the exact end point (when the
    duration is not a multiple of the period); ``q``, ``qd`` and ``qdd`` are interpolated
    linearly between the table's samples.  Linear interpolation of in-range samples stays in
    range (the ranges are boxes); the result passes :func:`robot.model.check_joints`.

    Raises
    ------
    ValueError
        ``rate_hz`` outside (0, MAX_RATE_HZ].
    TrajectoryTooLong
        The resampled table would hold more than :data:`MAX_SAMPLES` samples.
    JointLimitError
        The input table leaves the joint ranges.
    """
    if isinstance(rate_hz, bool) or not (0.0 < rate_hz <= MAX_RATE_HZ):
        raise ValueError(f"rate_hz must be in (0, {MAX_RATE_HZ:g}] Hz, got {rate_hz!r}")
    T = traj.duration_s
    check_plan_size(T, rate_hz)
    n = math.floor(T * rate_hz + 1e-9) + 1
    t = np.arange(n, dtype=np.float64) / rate_hz
    if T - t[-1] > 1e-9:
        t = np.append(t, T)
    else:
        t[-1] = T
    if traj.t_s.size == 1:
        z = np.zeros((t.size, 5))
        q = np.broadcast_to(traj.q[0], (t.size, 5)).copy()
        return JointTrajectory(t, check_joints(q), z, z)
    cols = [
        np.stack([np.interp(t, traj.t_s, a[:, j]) for j in range(5)], axis=-1)
        for a in (traj.q, traj.qd, cast(NDArray[np.float64], traj.qdd))  # set by __post_init__
    ]
    cols[0][0], cols[0][-1] = traj.q[0], traj.q[-1]
    return JointTrajectory(t, check_joints(cols[0]), cols[1], cols[2])
