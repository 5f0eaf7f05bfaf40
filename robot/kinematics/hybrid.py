"""The chapter's hybrid inverse kinematics (section 3.6.1): an IK estimate corrected via FK.

Section 3.6.1: "the solution of inverse kinematics is fed to forward kinematics so that the
desired position derived from calculated joint angles are computed.  The difference between
real desired position and calculated desired position is then calculated, which is added to
inverse kinematics function.  By repeating the loop a few times, the solution of inverse
kinematics should be optimal."  As a fixed-point iteration, with ``est`` an approximate IK,
``fk`` eq. 20 and the target ``p*``:

    c_0 = p*,   q_k = est(c_k),   c_{k+1} = c_k + gain (p* - fk(q_k)).

Position is corrected in metres and the approach in its angle ``phi = atan2(w, u)`` (so the
command stays a unit direction).  At a fixed point ``fk(est(c)) = p*`` exactly, so the loop
removes the estimator's bias wherever it converges; it converges locally when the spectral
radius of ``I - gain J_fk J_est`` is below 1, i.e. when the estimator's derivative is close
to the true inverse's.

What it is for here: with the exact closed form of eq. 20 (:func:`robot.kinematics.ik`) the
loop adds nothing (the first estimate already reproduces the pose to rounding).  It earns its
keep when the IK at hand is only approximate while the FK is trusted: the chapter's fuzzy
system (:func:`fuzzy_estimator`), or the closed form of a nominal model whose link lengths
differ from the calibrated ones the FK uses (:func:`nominal_model_estimator`, the default,
which stands for an arm whose controller still holds catalogue lengths).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robot.errors import Unreachable
from robot.kinematics.analytic import check_pose, ik
from robot.kinematics.batch import _check_batch, ik_batch
from robot.kinematics.forward import MAX_ABS_JOINT_RAD, fk
from robot.kinematics.fuzzy import SugenoIK
from robot.model import ASEA, ArmModel

__all__ = [
    "DEFAULT_LENGTH_ERRORS_M",
    "Estimator",
    "HybridBatchResult",
    "HybridIKResult",
    "fuzzy_estimator",
    "hybrid_ik",
    "hybrid_ik_batch",
    "nominal_model_estimator",
]

#: An approximate IK: poses (N, 5) and rolls (N,) -> joints (N, 5) (NaN rows: no estimate).
Estimator = Callable[[NDArray[np.float64], NDArray[np.float64]], NDArray[np.float64]]

#: Link-length errors of the default nominal model, metres (L1..L5): a few millimetres,
#: the size of the difference between catalogue and calibrated lengths of an old arm.
DEFAULT_LENGTH_ERRORS_M = (0.003, -0.004, 0.005, -0.002, 0.001)


def nominal_model_estimator(
    model: ArmModel = ASEA,
    *,
    length_errors_m: tuple[float, ...] = DEFAULT_LENGTH_ERRORS_M,
    range_margin_rad: float = math.radians(2.0),
) -> Estimator:
    """Closed-form IK of ``model`` with every link length off by ``length_errors_m``.

    The nominal model's joint ranges are widened by ``range_margin_rad`` so that estimates
    for targets near a range end are not lost to the length errors; the loop's result is
    checked against the true ranges (``within_limits``).
    """
    if len(length_errors_m) != 5:
        raise ValueError(f"length_errors_m must hold 5 values, got {length_errors_m!r}")
    if not range_margin_rad >= 0.0:
        raise ValueError(f"range_margin_rad must be >= 0, got {range_margin_rad!r}")
    l1, l2, l3, l4, l5 = (a + b for a, b in zip(model.link_lengths_m, length_errors_m, strict=True))
    limits = model.joint_limits_rad + np.array([-range_margin_rad, range_margin_rad])
    nominal = replace(
        model,
        name=f"{model.name} (nominal lengths)",
        link_lengths_m=(l1, l2, l3, l4, l5),
        joint_limits_rad=limits,
    )

    def estimate(poses: NDArray[np.float64], roll: NDArray[np.float64]) -> NDArray[np.float64]:
        if poses.shape[0] == 1:  # the scalar closed form is ~20x faster for one pose
            try:
                return ik(poses[0], roll=float(roll[0]), model=nominal)[None, :]
            except Unreachable:
                return np.full((1, 5), np.nan)
        return ik_batch(poses, roll, model=nominal)[0]

    return estimate


_DEFAULT_ESTIMATORS: dict[int, tuple[ArmModel, Estimator]] = {}


def _default_estimator(model: ArmModel) -> Estimator:
    """:func:`nominal_model_estimator` of ``model``, built once per model."""
    hit = _DEFAULT_ESTIMATORS.get(id(model))
    if hit is None or hit[0] is not model:
        hit = (model, nominal_model_estimator(model))
        _DEFAULT_ESTIMATORS[id(model)] = hit
    return hit[1]


def fuzzy_estimator(fis: SugenoIK) -> Estimator:
    """The Sugeno system as an estimator; q5 is set to the requested roll (not an input)."""

    def estimate(poses: NDArray[np.float64], roll: NDArray[np.float64]) -> NDArray[np.float64]:
        q = fis.infer(poses)
        q[:, 4] = roll
        return q

    return estimate


@dataclass(frozen=True)
class HybridBatchResult:
    """Result of :func:`hybrid_ik_batch`.

    Attributes
    ----------
    q : ndarray of shape (N, 5)
        Last estimate per pose (NaN where the estimator gave none).
    iterations : ndarray of int, shape (N,)
        Corrections applied before convergence (0: the first estimate was good enough).
    converged : ndarray of bool, shape (N,)
    position_error_m, orientation_error_rad : ndarray of shape (N,)
        Final ``|p* - fk(q)|`` and ``|phi* - phi(q)|``.
    within_limits : ndarray of bool, shape (N,)
    """

    q: NDArray[np.float64]
    iterations: NDArray[np.int64]
    converged: NDArray[np.bool_]
    position_error_m: NDArray[np.float64]
    orientation_error_rad: NDArray[np.float64]
    within_limits: NDArray[np.bool_]


@dataclass(frozen=True)
class HybridIKResult:
    """Result of :func:`hybrid_ik` for one pose.

    Attributes
    ----------
    q : ndarray of shape (5,)
    iterations : int
        Corrections applied (0: the first estimate was already within tolerance).
    converged : bool
    position_error_history_m : tuple of float
        ``|p* - fk(q_k)|`` for each estimate ``k = 0 .. iterations``.
    orientation_error_history_rad : tuple of float
        ``|phi* - phi(q_k)|`` likewise.
    within_limits : bool
    """

    q: NDArray[np.float64]
    iterations: int
    converged: bool
    position_error_history_m: tuple[float, ...]
    orientation_error_history_rad: tuple[float, ...]
    within_limits: bool

    @property
    def position_error_m(self) -> float:
        """Final position error, metres."""
        return self.position_error_history_m[-1]

    @property
    def orientation_error_rad(self) -> float:
        """Final approach-angle error, radians."""
        return self.orientation_error_history_rad[-1]


def _errors(
    target: NDArray[np.float64], phi_t: NDArray[np.float64], q: NDArray[np.float64], model: ArmModel
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    # An estimator may give up (NaN) or run away on a row; fk refuses such joints, so those
    # rows get NaN errors (never converged) and the others are evaluated.
    a = np.full(q.shape, np.nan)
    ok = np.all(np.abs(q) <= MAX_ABS_JOINT_RAD, axis=1)
    if ok.any():
        a[ok] = fk(q[ok], model)
    dp = target[:, :3] - a[:, :3]
    dphi = np.angle(np.exp(1j * (phi_t - np.arctan2(a[:, 4], a[:, 3]))))
    return dp, dphi


def _loop(
    P: NDArray[np.float64],
    roll: NDArray[np.float64],
    estimator: Estimator,
    model: ArmModel,
    tol_m: float,
    tol_rad: float,
    max_iterations: int,
    gain: float,
    history: list[tuple[NDArray[np.float64], NDArray[np.float64]]] | None,
) -> HybridBatchResult:
    N = P.shape[0]
    phi_t = np.arctan2(P[:, 4], P[:, 3])
    cmd_p = P[:, :3].copy()
    cmd_phi = phi_t.copy()
    q = np.asarray(estimator(P.copy(), roll), dtype=np.float64).reshape(N, 5)
    iters = np.zeros(N, dtype=np.int64)
    done = np.zeros(N, dtype=bool)
    dp, dphi = _errors(P, phi_t, q, model)
    for k in range(max_iterations + 1):
        ep, eo = np.linalg.norm(dp, axis=1), np.abs(dphi)
        if history is not None:
            history.append((ep.copy(), eo.copy()))
        done |= (ep <= tol_m) & (eo <= tol_rad)
        done |= ~np.isfinite(ep)  # the estimator gave up on these rows
        active = np.flatnonzero(~done)
        if active.size == 0 or k == max_iterations:
            break
        cmd_p[active] += gain * dp[active]
        cmd_phi[active] += gain * dphi[active]
        c = np.column_stack([cmd_p[active], np.cos(cmd_phi[active]), np.sin(cmd_phi[active])])
        q[active] = estimator(c, roll[active])
        iters[active] += 1
        dp[active], dphi[active] = _errors(P[active], phi_t[active], q[active], model)
    ep, eo = np.linalg.norm(dp, axis=1), np.abs(dphi)
    conv = (ep <= tol_m) & (eo <= tol_rad)
    ok_rows = np.all(np.isfinite(q), axis=1)
    within = np.zeros(N, dtype=bool)
    within[ok_rows] = model.within_limits(q[ok_rows])
    return HybridBatchResult(q, iters, conv, ep, eo, within)


def hybrid_ik_batch(
    poses: ArrayLike,
    roll: float | ArrayLike = 0.0,
    *,
    estimator: Estimator | None = None,
    tol_m: float = 1e-10,
    tol_rad: float = 1e-10,
    max_iterations: int = 50,
    gain: float = 1.0,
    model: ArmModel = ASEA,
) -> HybridBatchResult:
    """The section 3.6.1 loop for many poses at once (rows stop as they converge).

    Parameters
    ----------
    poses : array_like of shape (N, 5)
        Targets ``(x, y, z, u, w)``.
    roll : float or array_like of shape (N,)
        Roll about the approach axis (passed to the estimator, radians).
    estimator : Estimator, optional
        The approximate IK; default :func:`nominal_model_estimator` of ``model``.
    tol_m, tol_rad : float
        Convergence: position error and approach-angle error at or below both.
    max_iterations : int
        Largest number of corrections.
    gain : float
        Fraction of the error added back each time (the chapter: 1).
    model : ArmModel
        The trusted forward kinematics and the ranges reported in ``within_limits``.
    """
    if not (tol_m > 0 and tol_rad > 0 and max_iterations >= 0 and 0 < gain <= 2):
        raise ValueError(
            "need tol_m > 0, tol_rad > 0, max_iterations >= 0 and 0 < gain <= 2, got "
            f"{tol_m!r}, {tol_rad!r}, {max_iterations!r}, {gain!r}"
        )
    P, R, _ = _check_batch(poses, roll, None, model)
    est = estimator or _default_estimator(model)
    return _loop(P, np.array(R), est, model, tol_m, tol_rad, max_iterations, gain, None)


def hybrid_ik(
    pose: ArrayLike,
    *,
    roll: float = 0.0,
    estimator: Estimator | None = None,
    tol_m: float = 1e-10,
    tol_rad: float = 1e-10,
    max_iterations: int = 50,
    gain: float = 1.0,
    model: ArmModel = ASEA,
) -> HybridIKResult:
    """The section 3.6.1 loop for one pose, with its error history.

    Parameters are those of :func:`hybrid_ik_batch` for a single pose ``(x, y, z, u, w)``.

    Examples
    --------
    >>> r = hybrid_ik((0.8, 0.0, 1.0, 0.0, -1.0))
    >>> r.converged, r.position_error_m < 1e-10
    (True, True)
    """
    if not math.isfinite(float(roll)):
        raise ValueError(f"roll must be finite, got {roll!r}")
    P = np.array([check_pose(pose)])
    if not (tol_m > 0 and tol_rad > 0 and max_iterations >= 0 and 0 < gain <= 2):
        raise ValueError(
            "need tol_m > 0, tol_rad > 0, max_iterations >= 0 and 0 < gain <= 2, got "
            f"{tol_m!r}, {tol_rad!r}, {max_iterations!r}, {gain!r}"
        )
    hist: list[tuple[NDArray[np.float64], NDArray[np.float64]]] = []
    est = estimator or _default_estimator(model)
    r = _loop(P, np.array([float(roll)]), est, model, tol_m, tol_rad, max_iterations, gain, hist)
    q = r.q[0].copy()
    q.setflags(write=False)
    return HybridIKResult(
        q=q,
        iterations=int(r.iterations[0]),
        converged=bool(r.converged[0]),
        position_error_history_m=tuple(float(h[0][0]) for h in hist),
        orientation_error_history_rad=tuple(float(h[1][0]) for h in hist),
        within_limits=bool(r.within_limits[0]),
    )
