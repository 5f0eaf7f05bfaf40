"""The chapter's Sugeno fuzzy inference system for inverse kinematics (section 3.6.3).

A zero-order Sugeno system (Jang, Sun and Mizutani 1997, ch. 4) maps the Cartesian pose
``(x, y, z, u, w)`` to the five joints:

* antecedents: each input has two Gaussian membership functions (MF), ``Low`` and ``High``,
  ``mu(v) = exp(-(v - m)^2 / (2 sigma^2))``;
* rules: one per combination of labels, ``R = prod_j m_j = 2^5 = 32`` (eq. 21); rule ``k``
  uses label ``(k >> (4 - i)) & 1`` (0 = Low, 1 = High) for input ``i``, so rule 0 is
  "all Low" and rule 31 "all High", ``x`` being the most significant bit;
* firing strength: the product of the five memberships, ``f_k``;
* consequents: constants ``r_k = (r_k1 .. r_k5)``, one per joint (eq. 22);
* output: the weighted average ``q_j = sum_k f_k r_kj / sum_k f_k``.

Initial antecedents are "placed equally dividing the universe of discourse": for an input
whose universe is ``[lo, hi]`` the Low MF is centred at ``lo``, the High MF at ``hi``, both
with ``sigma = (hi - lo) / (2 sqrt(2 ln 2))`` so that they cross at membership 1/2 in the
middle (the placement of MATLAB's ``genfis1`` for two Gaussian MFs).

Consequent tuning (section 3.6.3.1, eq. 23) is batch gradient descent on
``E = sum_n sum_j (q_nj - qhat_nj)^2``.  The output is linear in the consequents,
``qhat = Wbar R`` with the normalised firing strengths ``Wbar`` (N, 32), so
``dE/dR = 2 Wbar^T (Wbar R - Q)`` exactly; with ``G = Wbar^T Wbar`` and ``B = Wbar^T Q``
one epoch costs a 32x32 by 32x5 product.  The default learning rate ``alpha = 1 / (2
lambda_max(G))`` is the step ``1/L`` of the gradient's Lipschitz constant ``L``, which makes
``E`` decrease monotonically; the least-squares optimum it converges to is available as
:func:`consequents_least_squares` for reference.  Antecedent tuning by the genetic algorithm
is in :mod:`robot.kinematics.fuzzy_ga`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "INPUTS",
    "MF_LABELS",
    "N_RULES",
    "ConsequentFit",
    "SugenoIK",
    "consequents_least_squares",
    "initial_sugeno",
    "rule_labels",
    "sse",
    "sse_per_pose",
    "tune_consequents",
]

INPUTS = ("x", "y", "z", "u", "w")
MF_LABELS = ("Low", "High")
#: Eq. 21: two labels on each of five inputs.
N_RULES = len(MF_LABELS) ** len(INPUTS)
_FORMAT = "visioncell-sugeno-ik-1"


def rule_labels() -> NDArray[np.int64]:
    """Label (0 = Low, 1 = High) of each input in each rule, shape (32, 5)."""
    k = np.arange(N_RULES)[:, None]
    return (k >> (4 - np.arange(5))[None, :]) & 1


@dataclass(frozen=True)
class SugenoIK:
    """A zero-order Sugeno system from ``(x, y, z, u, w)`` to ``(q1, .., q5)``.

    Attributes
    ----------
    mean : ndarray of shape (5, 2)
        MF centres ``[input, label]`` (label 0 = Low, 1 = High), in the input's unit.
    sigma : ndarray of shape (5, 2)
        MF standard deviations, positive.
    consequents : ndarray of shape (32, 5)
        Rule outputs ``r_k``, radians (rule order: see the module docstring).
    """

    mean: NDArray[np.float64]
    sigma: NDArray[np.float64]
    consequents: NDArray[np.float64]

    def __post_init__(self) -> None:
        m = np.array(self.mean, dtype=np.float64)
        s = np.array(self.sigma, dtype=np.float64)
        r = np.array(self.consequents, dtype=np.float64)
        if m.shape != (5, 2) or s.shape != (5, 2) or r.shape != (N_RULES, 5):
            raise ValueError(
                f"mean and sigma must have shape (5, 2) and consequents ({N_RULES}, 5), got "
                f"{m.shape}, {s.shape}, {r.shape}"
            )
        if not (np.all(np.isfinite(m)) and np.all(np.isfinite(r)) and np.all(s > 0)):
            raise ValueError(f"parameters must be finite with sigma > 0, got sigma {s.tolist()}")
        for name, a in (("mean", m), ("sigma", s), ("consequents", r)):
            a.setflags(write=False)
            object.__setattr__(self, name, a)

    def memberships(self, poses: ArrayLike) -> NDArray[np.float64]:
        """Gaussian memberships ``mu[n, input, label]``, shape (N, 5, 2)."""
        X = _check_inputs(poses)
        return np.exp(self._log_memberships(X))

    def _log_memberships(self, X: NDArray[np.float64]) -> NDArray[np.float64]:
        d = (X[:, :, None] - self.mean[None]) / self.sigma[None]
        return -0.5 * d * d

    def firing_strengths(self, poses: ArrayLike) -> NDArray[np.float64]:
        """Normalised firing strengths ``f_k / sum f``, shape (N, 32).

        Computed from log memberships with the row maximum removed, so that inputs far
        outside the universe (where every product underflows) still give finite weights.
        """
        X = _check_inputs(poses)
        lm = self._log_memberships(X)
        logf = lm[:, 0, :]
        for i in range(1, 5):  # outer sum over inputs; input 0 most significant
            logf = (logf[:, :, None] + lm[:, i, None, :]).reshape(X.shape[0], -1)
        logf -= logf.max(axis=1, keepdims=True)
        f = np.exp(logf)
        f /= f.sum(axis=1, keepdims=True)
        return f

    def infer(self, poses: ArrayLike) -> NDArray[np.float64]:
        """Joints for one pose (5,) or many (N, 5): the rules' weighted average."""
        P = np.asarray(poses, dtype=np.float64)
        out = self.firing_strengths(P) @ self.consequents
        return out[0] if P.ndim == 1 else out

    def with_consequents(self, consequents: ArrayLike) -> SugenoIK:
        """A copy with other rule outputs."""
        return replace(self, consequents=np.asarray(consequents, dtype=np.float64))

    def save(self, path: str | Path) -> Path:
        """Write the system to an ``.npz`` file (suffix added if missing); returns the path."""
        p = Path(path)
        if p.suffix != ".npz":
            p = p.with_suffix(p.suffix + ".npz")
        np.savez(
            p,
            format=np.array(_FORMAT),
            mean=self.mean,
            sigma=self.sigma,
            consequents=self.consequents,
        )
        return p

    @classmethod
    def load(cls, path: str | Path) -> SugenoIK:
        """Read a system written by :meth:`save`.

        Raises ``ValueError`` if the file is not such a system.
        """
        with np.load(Path(path), allow_pickle=False) as z:
            if "format" not in z or str(z["format"]) != _FORMAT:
                raise ValueError(f"{path!s} is not a VisionCell Sugeno IK file ({_FORMAT})")
            return cls(z["mean"], z["sigma"], z["consequents"])


def _check_inputs(poses: ArrayLike) -> NDArray[np.float64]:
    X = np.asarray(poses, dtype=np.float64)
    X2 = X.reshape(1, -1) if X.ndim == 1 else X
    if X2.ndim != 2 or X2.shape[1] != 5 or not np.all(np.isfinite(X2)):
        raise ValueError(f"poses must be finite with shape (5,) or (N, 5), got {X.shape}")
    return X2


def initial_sugeno(universe: ArrayLike, consequents: ArrayLike) -> SugenoIK:
    """The untuned system: MFs dividing each universe equally, constant rule outputs.

    Parameters
    ----------
    universe : array_like of shape (5, 2)
        ``[lo, hi]`` of each input's universe of discourse.
    consequents : array_like of shape (5,) or (32, 5)
        Initial rule outputs (one vector shared by every rule, or one per rule), radians.
    """
    U = np.asarray(universe, dtype=np.float64)
    if U.shape != (5, 2) or not np.all(U[:, 1] > U[:, 0]):
        raise ValueError(f"universe must have shape (5, 2) with hi > lo, got {U.tolist()}")
    sigma = (U[:, 1] - U[:, 0]) / (2.0 * math.sqrt(2.0 * math.log(2.0)))
    r = np.asarray(consequents, dtype=np.float64)
    if r.shape == (5,):
        r = np.tile(r, (N_RULES, 1))
    return SugenoIK(U.copy(), np.column_stack([sigma, sigma]), r)


def sse_per_pose(fis: SugenoIK, poses: ArrayLike, q: ArrayLike) -> NDArray[np.float64]:
    """Sum over the five joints of the squared error, per pose (rad^2), shape (N,)."""
    Q = np.asarray(q, dtype=np.float64)
    return ((fis.infer(np.atleast_2d(poses)) - np.atleast_2d(Q)) ** 2).sum(axis=1)


def sse(fis: SugenoIK, poses: ArrayLike, q: ArrayLike) -> float:
    """Eq. 23's ``E``: the sum of squared joint errors over all poses (rad^2)."""
    return float(sse_per_pose(fis, poses, q).sum())


@dataclass(frozen=True)
class ConsequentFit:
    """Result of gradient-descent consequent tuning (eq. 23).

    Attributes
    ----------
    fis : SugenoIK
        The system with the tuned consequents.
    sse_history : ndarray
        ``E`` before the first epoch and after each epoch that ran (rad^2).
    learning_rate : float
        ``alpha`` of eq. 23.
    epochs : int
        Epochs run (fewer than asked when ``E`` stopped decreasing).
    """

    fis: SugenoIK
    sse_history: NDArray[np.float64]
    learning_rate: float
    epochs: int


def tune_consequents(
    fis: SugenoIK,
    poses: ArrayLike,
    q: ArrayLike,
    *,
    epochs: int = 3000,
    learning_rate: float | None = None,
    rel_tol: float = 1e-12,
) -> ConsequentFit:
    """Gradient descent on the consequents, eq. 23: ``r(t+1) = r(t) - alpha dE/dr``.

    Parameters
    ----------
    fis : SugenoIK
        Start point (its antecedents stay fixed).
    poses, q : array_like of shape (N, 5)
        Training inputs and target joints.
    epochs : int
        Largest number of full-batch steps.
    learning_rate : float, optional
        ``alpha``; default ``1 / (2 lambda_max(Wbar^T Wbar))`` (module docstring).
    rel_tol : float
        Stop early once an epoch lowers ``E`` by less than this fraction of ``E``.
    """
    if epochs < 0:
        raise ValueError(f"epochs must be >= 0, got {epochs!r}")
    X = _check_inputs(poses)
    Q = np.asarray(q, dtype=np.float64).reshape(X.shape[0], 5)
    Wb = fis.firing_strengths(X)
    G = Wb.T @ Wb
    B = Wb.T @ Q
    qq = float((Q * Q).sum())
    if learning_rate is None:
        learning_rate = 1.0 / (2.0 * float(np.linalg.eigvalsh(G)[-1]))
    elif not (learning_rate > 0.0):
        raise ValueError(f"learning_rate must be positive, got {learning_rate!r}")
    R = np.array(fis.consequents)
    step = 2.0 * learning_rate
    # E = tr(R^T G R) - 2 tr(R^T B) + |Q|^2 needs G R, which the next gradient reuses.
    GR = G @ R
    hist = [max(float((R * (GR - 2.0 * B)).sum()) + qq, 0.0)]
    done = 0
    for _ in range(epochs):
        R -= step * (GR - B)
        GR = G @ R
        done += 1
        e = max(float((R * (GR - 2.0 * B)).sum()) + qq, 0.0)
        hist.append(e)
        if hist[-2] - e <= rel_tol * hist[-2]:
            break
    return ConsequentFit(fis.with_consequents(R), np.array(hist), float(learning_rate), done)


def consequents_least_squares(fis: SugenoIK, poses: ArrayLike, q: ArrayLike) -> SugenoIK:
    """The consequents minimising eq. 23's ``E`` exactly (the limit of gradient descent)."""
    X = _check_inputs(poses)
    Q = np.asarray(q, dtype=np.float64).reshape(X.shape[0], 5)
    R, *_ = np.linalg.lstsq(fis.firing_strengths(X), Q, rcond=None)
    return fis.with_consequents(R)
