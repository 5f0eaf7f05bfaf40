"""Batched closed-form inverse kinematics (chapter eq. 20) for (N, 5) pose arrays.

The same closed form as :mod:`robot.kinematics.analytic`, written over whole columns so that
no Python loop runs over the poses: the four branches are built as a (4, 5, N) array, every
angle is brought into its range by multiples of 2 pi, and the branch within limits nearest
the seed is picked per row.  Rows are processed in cache-sized blocks of :data:`CHUNK`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robot.kinematics.analytic import _AXIS_EPS, _REACH_EPS, LIMIT_TOL, TAU, UNIT_TOL
from robot.model import ASEA, ArmModel

__all__ = ["ik_batch", "ik_batch_branches"]

#: Rows solved per block.
CHUNK = 8192


def _check_batch(
    poses: ArrayLike, roll: float | ArrayLike, seed: ArrayLike | None, model: ArmModel
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    P = np.asarray(poses, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 5:
        raise ValueError(f"poses must have shape (N, 5), got {P.shape}")
    n = np.sqrt(P[:, 3] ** 2 + P[:, 4] ** 2)
    if not (np.isfinite(P).all() and (np.abs(n - 1.0) <= UNIT_TOL).all()):
        bad = ~(np.abs(n - 1.0) <= UNIT_TOL) | ~np.isfinite(P[:, :3]).all(axis=1)
        i = int(np.argmax(bad))
        raise ValueError(
            "poses must hold finite positions and unit approach directions "
            f"(u^2 + w^2 = 1 within {UNIT_TOL:g}); row {i} is {P[i].tolist()}"
        )
    R = np.broadcast_to(np.asarray(roll, dtype=np.float64), (P.shape[0],))
    if not np.all(np.isfinite(R)):
        raise ValueError(f"roll must be finite, got {roll!r}")
    S = np.asarray(model.q_home if seed is None else seed, dtype=np.float64)
    if S.shape not in ((5,), (P.shape[0], 5)) or not np.all(np.isfinite(S)):
        raise ValueError(f"seed must have shape (5,) or ({P.shape[0]}, 5), got {S.shape}")
    return P, R, S


def ik_batch_branches(
    poses: ArrayLike,
    roll: float | ArrayLike = 0.0,
    *,
    seed: ArrayLike | None = None,
    model: ArmModel = ASEA,
) -> tuple[NDArray[np.float64], NDArray[np.bool_], NDArray[np.intp]]:
    """Like :func:`ik_batch`, also returning the chosen branch index (into ``BRANCHES``).

    Returns
    -------
    q : ndarray of shape (N, 5)
        NaN on rows without a solution within limits.
    ok : ndarray of bool, shape (N,)
    branch : ndarray of int, shape (N,)
        Index into :data:`robot.kinematics.analytic.BRANCHES`; -1 where ``ok`` is False.
    """
    P, roll_a, S = _check_batch(poses, roll, seed, model)
    N = P.shape[0]
    q = np.empty((N, 5))
    ok = np.empty(N, dtype=bool)
    branch = np.empty(N, dtype=np.intp)
    # Blocks of CHUNK rows keep the few dozen temporaries of the closed form in the CPU
    # cache (about twice the throughput of whole-array passes at 100,000 poses).
    for a in range(0, N, CHUNK):
        b = min(a + CHUNK, N)
        Sc = S if S.ndim == 1 else S[a:b]
        q[a:b], ok[a:b], branch[a:b] = _solve(P[a:b], roll_a[a:b], Sc, model)
    return q, ok, branch


def _solve(
    P: NDArray[np.float64], roll_a: NDArray[np.float64], S: NDArray[np.float64], model: ArmModel
) -> tuple[NDArray[np.float64], NDArray[np.bool_], NDArray[np.intp]]:
    """The closed form on one block of validated rows."""
    N = P.shape[0]
    x, y, z, u, w = np.ascontiguousarray(P.T)
    L1, L2, L3, L45 = model.L1, model.L2, model.L3, model.L45
    Sj = S.T if S.ndim == 2 else S[:, None]  # (5, N) or (5, 1)
    rho = np.sqrt(x * x + y * y)
    theta = np.arctan2(y, x)
    on_axis = rho <= _AXIS_EPS
    if on_axis.any():
        theta = np.where(on_axis, Sj[0], theta)
    nrm = np.sqrt(u * u + w * w)
    cu, sw = u / nrm, w / nrm
    phi = np.arctan2(sw, cu)
    rw = rho - L45 * cu
    zw = z - L1 - L45 * sw
    d = (rw * rw + zw * zw - (L2 * L2 + L3 * L3)) / (2.0 * L2 * L3)
    reach = np.abs(d) <= 1.0 + _REACH_EPS
    np.clip(d, -1.0, 1.0, out=d)
    t3 = np.arccos(d)
    bend = np.arctan2(L3 * np.sqrt(1.0 - d * d), L2 + L3 * d)
    front = np.arctan2(zw, rw)
    over = np.pi - front  # atan2(zw, -rw) up to a multiple of 2 pi
    phi_o = np.pi - phi
    # Branch order as BRANCHES: front up/down, reach-over up/down (see analytic.py).  Each
    # distinct joint value is fitted into its range once.
    q2 = (front + bend, front - bend, over + bend, over - bend)
    q3 = (-t3, t3)
    q4 = (phi - q2[0] + t3, phi - q2[1] - t3, phi_o - q2[2] + t3, phi_o - q2[3] - t3)
    fit = _Fitter(model, Sj)
    q1f = (fit(0, theta), fit(0, theta + np.pi))
    q2f = tuple(fit(1, v) for v in q2)
    q3f = tuple(fit(2, v) for v in q3)
    q4f = tuple(fit(3, v) for v in q4)
    q5f = (fit(4, roll_a), fit(4, roll_a + np.pi))
    cols = [
        (q1f[b // 2], q2f[b], q3f[b % 2], q4f[b], q5f[b // 2]) for b in range(4)
    ]  # per branch, per joint: (value, inside)
    within = np.empty((4, N), dtype=bool)
    for b, joints in enumerate(cols):
        m = reach.copy()
        for _, inside in joints:
            m &= inside
        within[b] = m
    count = within.sum(axis=0)
    ok = count > 0
    branch = np.argmax(within, axis=0)
    several = np.flatnonzero(count > 1)
    if several.size:  # nearest to the seed among the branches within limits
        dist = np.full((4, several.size), np.inf)
        for b, joints in enumerate(cols):
            acc = np.zeros(several.size)
            for j, (val, _) in enumerate(joints):
                sj = Sj[j] if Sj.shape[1] == 1 else Sj[j, several]
                acc += (val[several] - sj) ** 2
            dist[b] = np.where(within[b, several], acc, np.inf)
        branch[several] = np.argmin(dist, axis=0)
    qt = np.empty((5, N))
    for j in range(5):
        qt[j] = cols[0][j][0]
    for b in range(1, 4):
        rows = np.flatnonzero(branch == b)
        if rows.size:
            for j in range(5):
                qt[j, rows] = cols[b][j][0][rows]
    qt[:, ~ok] = np.nan
    q = qt.T.copy()
    branch = np.where(ok, branch, -1)
    return q, ok, branch


class _Fitter:
    """Brings one joint's values into its range by multiples of 2 pi."""

    def __init__(self, model: ArmModel, Sj: NDArray[np.float64]) -> None:
        self.lo = model.lower - LIMIT_TOL
        self.hi = model.upper + LIMIT_TOL
        self.full = self.hi - self.lo >= TAU
        self.Sj = Sj

    def __call__(
        self, j: int, v: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        lo, hi = self.lo[j], self.hi[j]
        inside = (v >= lo) & (v <= hi)
        if not inside.all():
            # The smallest representative >= lo; within the range iff it is <= hi.
            t = lo - v
            t *= 1.0 / TAU
            np.ceil(t, out=t)
            t *= TAU
            t += v
            v = t
            inside = v <= hi
        if self.full[j]:  # a second representative may be in range: take the nearer one
            near_end = np.flatnonzero((v <= hi - TAU) | (v >= lo + TAU))
            if near_end.size:
                v = v.copy()
                s = self.Sj[j] if self.Sj.shape[1] == 1 else self.Sj[j, near_end]
                cur = v[near_end]
                alt = np.where(cur <= hi - TAU, cur + TAU, cur - TAU)
                v[near_end] = np.where(np.abs(alt - s) < np.abs(cur - s), alt, cur)
        return v, inside


def ik_batch(
    poses: ArrayLike,
    roll: float | ArrayLike = 0.0,
    *,
    seed: ArrayLike | None = None,
    model: ArmModel = ASEA,
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Closed-form inverse of eq. 20 for many poses at once, without a loop over them.

    Parameters
    ----------
    poses : array_like of shape (N, 5)
        Rows ``(x, y, z, u, w)`` as in :func:`robot.kinematics.ik`.
    roll : float or array_like of shape (N,)
        Roll about the approach axis, radians.
    seed : array_like of shape (5,) or (N, 5), optional
        Configuration(s) to stay close to; default ``model.q_home``.
    model : ArmModel
        Link lengths and joint ranges.

    Returns
    -------
    q : ndarray of shape (N, 5)
        The branch within limits nearest the seed (as :func:`robot.kinematics.ik`); NaN rows
        where there is none (out of reach or blocked by a range: call :func:`ik` on such a
        row for the reason).
    ok : ndarray of bool, shape (N,)

    Raises
    ------
    ValueError
        Wrong shapes, non-finite values or a non-unit ``(u, w)`` (the first bad row is quoted).
    """
    q, ok, _ = ik_batch_branches(poses, roll, seed=seed, model=model)
    return q, ok
