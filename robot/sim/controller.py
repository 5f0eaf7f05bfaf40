"""Joint controller of the simulated arm: computed torque with integral action.

This is the chapter's Figure 8 loop (section 3.6): the controller compares the desired joint
angles with the measured ones and sends torques to the five joint motors; the plant (MuJoCo)
returns the angles and angular velocities.  The control law is the computed-torque method
(Craig, *Introduction to Robotics*, 3rd ed., section 10.6; Spong, Hutchinson and Vidyasagar,
*Robot Modeling and Control*, section 8.3):

    tau = M(q) (qdd_ref + Kp e + Kd e_dot + Ki int(e) dt) + b(q, qd)

with ``e = q_ref - q``, ``M`` the joint-space inertia (armature included) and ``b`` the
Coriolis, centrifugal and gravity torques, both taken from MuJoCo at the current state.
Joint damping and friction are not in ``b``: the integral term removes what they leave.
The gains place the three error poles at ``-omega`` (``Kd = 3 omega``,
``Kp = 3 omega^2``, ``Ki = omega^3``).  Torques are clipped to the motors' limits.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robot.drivers.base import MoveReport
from robot.trajectory import JointTrajectory

__all__ = ["ControllerGains", "JointController", "stop_trajectory"]


@dataclass(frozen=True)
class ControllerGains:
    """Gains of :class:`JointController`.

    Attributes
    ----------
    omega_rad_s : float
        Bandwidth of the error dynamics (triple pole at ``-omega``).
    integral_limit_rad_s2 : float
        Bound on the integral term's acceleration (anti-windup).
    settle_tolerance_rad : float
        A move ends when every joint error is below this and the arm is still.
    settle_speed_rad_s : float
        "Still": every joint speed below this.
    settle_timeout_s : float
        A move ends at the latest this long after its trajectory.
    law : {"computed_torque", "pd_gravity"}
        ``"computed_torque"`` (the default, see the module doc) or the simpler
        ``"pd_gravity"`` baseline: ``tau = diag(M) (Kp e + Kd e_dot + Ki int(e)) + b`` with
        no acceleration feed-forward and no coupling through ``M``.
    """

    omega_rad_s: float = 30.0
    integral_limit_rad_s2: float = 8.0
    settle_tolerance_rad: float = 1e-4
    settle_speed_rad_s: float = 2e-3
    settle_timeout_s: float = 1.0
    law: str = "computed_torque"

    def __post_init__(self) -> None:
        if self.law not in ("computed_torque", "pd_gravity"):
            raise ValueError(f"law must be 'computed_torque' or 'pd_gravity', got {self.law!r}")
        if not self.omega_rad_s > 0:
            raise ValueError(f"omega_rad_s must be positive, got {self.omega_rad_s!r}")
        for name in (
            "integral_limit_rad_s2",
            "settle_tolerance_rad",
            "settle_speed_rad_s",
            "settle_timeout_s",
        ):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be positive, got {getattr(self, name)!r}")


class _Reference:
    """A trajectory table with accelerations, sampled fast (one search per call)."""

    def __init__(self, traj: JointTrajectory, t0: float) -> None:
        self.t0 = t0
        self.t = np.asarray(traj.t_s, dtype=np.float64)
        self.q = np.asarray(traj.q, dtype=np.float64)
        self.qd = np.asarray(traj.qd, dtype=np.float64)
        if self.t.size > 1:
            self.qdd = np.gradient(self.qd, self.t, axis=0)
            self.qdd[-1] = 0.0
        else:
            self.qdd = np.zeros_like(self.q)
        self.duration = float(self.t[-1])
        self.goal = self.q[-1].copy()

    def at(self, t: float) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        tau = t - self.t0
        if tau >= self.duration:
            return self.goal, np.zeros(5), np.zeros(5)
        if tau <= 0.0:
            return self.q[0], self.qd[0], self.qdd[0]
        i = int(np.searchsorted(self.t, tau, side="right")) - 1
        w = (tau - self.t[i]) / (self.t[i + 1] - self.t[i])
        return (
            self.q[i] + w * (self.q[i + 1] - self.q[i]),
            self.qd[i] + w * (self.qd[i + 1] - self.qd[i]),
            self.qdd[i],
        )


def stop_trajectory(
    q: ArrayLike, qd: ArrayLike, max_acceleration_rad_s2: ArrayLike, *, rate_hz: float = 500.0
) -> JointTrajectory:
    """Bring every joint from speed ``qd`` to rest at its own acceleration limit.

    ``q(t) = q0 + v0 t - a sign(v0) t^2 / 2`` until ``t = |v0| / a``, then constant.
    """
    q0 = np.asarray(q, dtype=np.float64)
    v0 = np.asarray(qd, dtype=np.float64)
    a = np.asarray(max_acceleration_rad_s2, dtype=np.float64)
    t_stop = np.abs(v0) / a
    T = float(t_stop.max())
    if T <= 1e-9:
        return JointTrajectory(np.zeros(1), q0[None, :], np.zeros((1, 5)))
    t = np.linspace(0.0, T, max(2, math.ceil(T * rate_hz) + 1))
    tt = np.minimum(t[:, None], t_stop[None, :])
    qs = q0 + v0 * tt - 0.5 * a * np.sign(v0) * tt**2
    qds = v0 - a * np.sign(v0) * tt
    qds[t[:, None].repeat(5, 1) >= t_stop[None, :]] = 0.0
    return JointTrajectory(t, qs, qds)


class JointController:
    """Computed-torque tracking of joint trajectories, with per-move error statistics.

    Parameters
    ----------
    dt_s : float
        Control period (one physics step).
    torque_limits : array_like of shape (5,)
        Motor torque limits, N m.
    max_acceleration_rad_s2 : array_like of shape (5,)
        Used to plan controlled stops.
    gains : ControllerGains
    q0 : array_like of shape (5,)
        Initial hold position.
    """

    def __init__(
        self,
        dt_s: float,
        torque_limits: ArrayLike,
        max_acceleration_rad_s2: ArrayLike,
        gains: ControllerGains,
        q0: ArrayLike,
    ) -> None:
        if not dt_s > 0:
            raise ValueError(f"dt_s must be positive, got {dt_s!r}")
        self.dt = float(dt_s)
        self.gains = gains
        w = gains.omega_rad_s
        self.kp, self.kd, self.ki = 3.0 * w * w, 3.0 * w, w**3
        self._computed_torque = gains.law == "computed_torque"
        self.tau_max = np.asarray(torque_limits, dtype=np.float64)
        self.amax = np.asarray(max_acceleration_rad_s2, dtype=np.float64)
        self._ie = np.zeros(5)
        self._ie_max = gains.integral_limit_rad_s2 / self.ki
        self._ref = _Reference(
            JointTrajectory(np.zeros(1), np.asarray(q0, float)[None, :], np.zeros((1, 5))), 0.0
        )
        self._move: _Move | None = None
        self.last_tau = np.zeros(5)
        self.saturated = False

    # -- commands (called between steps, on the physics thread) --------------------------
    @property
    def moving(self) -> bool:
        """True while a move is being executed (until it settles)."""
        return self._move is not None

    @property
    def goal(self) -> NDArray[np.float64]:
        """The configuration the controller is heading for or holding."""
        return self._ref.goal

    def start(self, traj: JointTrajectory, t: float, on_done: Callable[[MoveReport], None]) -> None:
        """Track ``traj`` from time ``t``; ``on_done(report)`` is called when it has settled."""
        if self._move is not None:
            raise RuntimeError("a move is already executing")
        self._ref = _Reference(traj, t)
        self._move = _Move(t, traj.goal.copy(), on_done)

    def stop(self, t: float, reason: str = "stopped") -> None:
        """Controlled stop: decelerate from the reference's speed, then hold."""
        q, qd, _ = self._ref.at(t)
        self._ref = _Reference(stop_trajectory(q, qd, self.amax), t)
        if self._move is not None:
            self._move.reason = reason
            self._move.stopping_at = t

    def brake(self, t: float, q: ArrayLike) -> None:
        """Emergency stop: hold the measured position at once; an executing move ends now."""
        qa = np.asarray(q, dtype=np.float64)
        self._ref = _Reference(JointTrajectory(np.zeros(1), qa[None, :], np.zeros((1, 5))), t)
        self._ie[:] = 0.0
        if self._move is not None:
            move, self._move = self._move, None
            move.finish(t, qa, "estop")

    def hold(self, t: float, q: ArrayLike) -> None:
        """Hold ``q`` (no move in progress)."""
        qa = np.asarray(q, dtype=np.float64)
        self._ref = _Reference(JointTrajectory(np.zeros(1), qa[None, :], np.zeros((1, 5))), t)
        self._ie[:] = 0.0

    # -- the loop ------------------------------------------------------------------------
    def torque(
        self,
        t: float,
        q: NDArray[np.float64],
        qd: NDArray[np.float64],
        M: NDArray[np.float64],
        bias: NDArray[np.float64],
    ) -> NDArray[np.float64]:
        """Torques for the step starting at ``t`` from the measured ``q``, ``qd``, ``M`` and ``b``."""
        qr, qdr, qddr = self._ref.at(t)
        e = qr - q
        self._ie = np.clip(self._ie + e * self.dt, -self._ie_max, self._ie_max)
        fb = self.kp * e + self.kd * (qdr - qd) + self.ki * self._ie
        # Computed torque decouples the joints through M; the baseline uses M's diagonal.
        tau = M @ (qddr + fb) + bias if self._computed_torque else np.diag(M) * fb + bias
        clipped = np.clip(tau, -self.tau_max, self.tau_max)
        self.saturated = bool(np.any(clipped != tau))
        self.last_tau = clipped
        move = self._move
        if move is not None:
            move.record(t, e, q, qd, self._ref, self.gains)
            if move.done:
                self._move = None
                move.finish(t, q, move.reason)
        return clipped


class _Move:
    """Book-keeping of one executing move."""

    def __init__(
        self, t0: float, goal: NDArray[np.float64], on_done: Callable[[MoveReport], None]
    ) -> None:
        self.t0 = t0
        self.goal = goal
        self.on_done = on_done
        self.reason = "done"
        self.stopping_at: float | None = None
        self.sum_sq = 0.0
        self.n = 0
        self.max_err = 0.0
        self.done = False

    def record(
        self,
        t: float,
        e: NDArray[np.float64],
        q: NDArray[np.float64],
        qd: NDArray[np.float64],
        ref: _Reference,
        gains: ControllerGains,
    ) -> None:
        err = float(np.abs(e).max())
        in_trajectory = t - ref.t0 <= ref.duration
        if in_trajectory:
            self.sum_sq += err * err
            self.n += 1
            self.max_err = max(self.max_err, err)
            return
        still = float(np.abs(qd).max()) < gains.settle_speed_rad_s
        settled = float(np.abs(ref.goal - q).max()) < gains.settle_tolerance_rad and still
        if settled or t - ref.t0 - ref.duration > gains.settle_timeout_s:
            self.done = True

    def finish(self, t: float, q: ArrayLike, reason: str) -> None:
        qa = np.asarray(q, dtype=np.float64)
        report = MoveReport(
            completed=reason == "done",
            reason=reason,
            duration_s=t - self.t0,
            final_q=tuple(float(v) for v in qa),
            final_error_rad=float(np.abs(qa - self.goal).max()),
            rms_tracking_error_rad=math.sqrt(self.sum_sq / self.n) if self.n else 0.0,
            max_tracking_error_rad=self.max_err,
        )
        self.on_done(report)
