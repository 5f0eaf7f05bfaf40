"""Closed active contour ("snake") of Kass, Witkin and Terzopoulos (1988), chapter eqs. 6-11.

The contour ``C(n) = (x_n, y_n)``, ``n = 0..N-1`` (eq. 7, closed: ``x_N = x_0``) minimises
``E = E_int + E_ext`` (eq. 8) with

- ``E_int = sum_n alpha |x_{n+1} - x_n|^2 + beta |x_{n+1} - 2 x_n + x_{n-1}|^2`` (eq. 9 with
  index differences; the points are kept equally spaced by arc length, so these are the
  ``C'`` and ``C''`` of eq. 9 up to the constant spacing),
- ``E_ext = sum_n E_img(x_n)`` (eq. 10) with the edge energy of eq. 11 (see
  :mod:`vision.segmentation.energy` for the guard against division by zero).

The gradient of ``E_int`` is ``A x`` with ``A`` the cyclic pentadiagonal matrix whose rows
hold ``(2 beta, -2 alpha - 8 beta, 4 alpha + 12 beta, -2 alpha - 8 beta, 2 beta)``.  Each step
is semi-implicit in the internal energy and explicit in the image force ``f = -grad E_ext``
(Kass et al. 1988, eq. 19):

    (A + gamma I) x_{t+1} = gamma x_t + f(x_t),

so ``A + gamma I`` is factored once per contour size and weights (banded Cholesky of its
pentadiagonal block plus a 2x2 Schur complement for the cyclic corners, cached) and each
step costs O(N).  ``gamma`` is the viscosity: the inverse of the time step.  Every
``resample_every`` iterations self-intersection loops are cut out, the points are
redistributed evenly by arc length, and the mean movement per iteration since the previous
resampling is compared with ``max_px_move`` to decide convergence.

The iterations run compiled (:mod:`vision.segmentation._kernels`, Numba); the image forces
are precomputed with OpenCV filters (:mod:`vision.segmentation.energy`).  By default the
external force is eq. 11's alone, as in the chapter; ``balloon < 0`` adds Cohen's pressure
for contours initialised around the object (recommended: eq. 11 pulls only within a few
``sigma`` of an edge), ``external="gvf"`` swaps in gradient vector flow.

Coordinates are ``(x, y)`` = (column, row) pixels (see :mod:`vision.segmentation.contours`);
scikit-image's ``active_contour`` takes and returns ``(row, col)``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.linalg import cho_solve_banded, cholesky_banded

from vision.segmentation import _kernels
from vision.segmentation.contours import mask_from_contour, resample_closed
from vision.segmentation.energy import ExternalField, ExternalMode, external_field
from vision.segmentation.pyramid import gaussian_pyramid
from vision.segmentation.validation import (
    check_contour,
    check_image,
    check_int,
    check_nonnegative,
    check_positive,
)

__all__ = ["SnakeResult", "active_contour", "internal_energy", "internal_matrix"]

Progress = Callable[[float, str], None]


@dataclass(frozen=True)
class SnakeResult:
    """Outcome of :func:`active_contour`.

    Attributes
    ----------
    contour : ndarray of shape (N, 2), float64
        Final closed contour, ``(x, y)`` = (column, row) pixels, full resolution.
    mask : ndarray of shape (H, W), bool
        Pixels inside the contour.
    iterations : int
        Iterations run, summed over the pyramid levels.
    converged : bool
        Whether the movement test passed (on the finest level) before ``max_num_iter``.
    energy : ndarray of shape (K,), float64
        Eq. 8 (``E_int`` of eq. 9 plus ``E_ext`` of eqs. 10-11) at iteration 0 and at each
        convergence check of the finest level.
    energy_iterations : ndarray of shape (K,), int64
        The iteration (of the finest level) each ``energy`` entry belongs to.
    snapshots : tuple of (int, ndarray of shape (N, 2))
        Contours at the iterations asked for in ``snapshot_at`` (finest level, full resolution).
    """

    contour: NDArray[np.float64]
    mask: NDArray[np.bool_]
    iterations: int
    converged: bool
    energy: NDArray[np.float64]
    energy_iterations: NDArray[np.int64]
    snapshots: tuple[tuple[int, NDArray[np.float64]], ...] = ()


def internal_matrix(n: int, alpha: float, beta: float) -> NDArray[np.float64]:
    """The cyclic pentadiagonal matrix ``A`` with ``grad E_int = A x`` (eq. 9), shape (n, n)."""
    n = check_int(n, "n_points", minimum=5)
    row = np.zeros(n)
    row[0] = 4.0 * alpha + 12.0 * beta
    row[1] = row[-1] = -2.0 * alpha - 8.0 * beta
    row[2] = row[-2] = 2.0 * beta
    idx = (np.arange(n)[None, :] - np.arange(n)[:, None]) % n
    return row[idx]


@lru_cache(maxsize=64)
def _factors(
    n: int, alpha: float, beta: float, gamma: float
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Factor ``A + gamma I`` once per (size, weights) for O(n) solves.

    The matrix is split as ``[[B, C], [C^T, D]]`` with ``B`` its leading (n-2, n-2) block,
    which is pentadiagonal *without* the cyclic corners (those couple points 0, 1 with
    n-2, n-1 and fall into the border ``C``).  ``B`` gets a banded Cholesky factor; the
    border is handled by the Schur complement ``S = D - C^T B^-1 C`` (2x2).  See
    :func:`vision.segmentation._kernels.solve_cyclic`.
    """
    m = n - 2
    M = internal_matrix(n, alpha, beta) + gamma * np.eye(n)
    ab = np.zeros((3, m))
    ab[0] = np.diag(M, 0)[:m]
    ab[1, : m - 1] = np.diag(M, -1)[: m - 1]
    ab[2, : m - 2] = np.diag(M, -2)[: m - 2]
    lband = cholesky_banded(ab, lower=True)
    border = np.ascontiguousarray(M[:m, m:])
    y_mat = cho_solve_banded((lband, True), border)
    s_inv = np.linalg.inv(M[m:, m:] - border.T @ y_mat)
    for a in (lband, border, y_mat, s_inv):
        a.setflags(write=False)
    return lband, border, np.ascontiguousarray(y_mat), s_inv


def internal_energy(contour: NDArray[np.float64], alpha: float, beta: float) -> float:
    """``E_int`` of eq. 9 for a closed contour (index differences, ``Delta s`` = 1)."""
    d1 = np.roll(contour, -1, axis=0) - contour
    d2 = np.roll(contour, -1, axis=0) - 2.0 * contour + np.roll(contour, 1, axis=0)
    return float(alpha * np.sum(d1 * d1) + beta * np.sum(d2 * d2))


@dataclass(frozen=True)
class _LevelRun:
    contour: NDArray[np.float64]
    iterations: int
    converged: bool
    energy: NDArray[np.float64]
    energy_iterations: NDArray[np.int64]
    snapshots: list[tuple[int, NDArray[np.float64]]]


def _run_level(
    field: ExternalField,
    x: NDArray[np.float64],
    *,
    alpha: float,
    beta: float,
    gamma: float,
    balloon: float,
    max_num_iter: int,
    max_px_move: float,
    max_step_px: float,
    resample_every: int,
    snapshot_at: frozenset[int],
) -> _LevelRun:
    n = x.shape[0]
    lband, border, y_mat, s_inv = _factors(n, alpha, beta, gamma)
    samples = np.ascontiguousarray(np.dstack([field.force, field.stop]), dtype=np.float32)
    energy = np.ascontiguousarray(field.energy[:, :, None], dtype=np.float32)
    snap_its = np.array(sorted(i for i in snapshot_at if i <= max_num_iter), dtype=np.int64)
    snaps = np.zeros((snap_its.size, n, 2))
    n_checks = max_num_iter // resample_every + 2
    energies = np.zeros(n_checks)
    energy_its = np.zeros(n_checks, dtype=np.int64)
    xf, iterations, converged, n_rec = _kernels.run_snake(
        samples,
        energy,
        np.ascontiguousarray(x, dtype=np.float64),
        lband,
        border,
        y_mat,
        s_inv,
        alpha,
        beta,
        gamma,
        balloon,
        max_step_px,
        resample_every,
        max_num_iter,
        max_px_move,
        snap_its,
        snaps,
        energies,
        energy_its,
    )
    # Snapshots past the last iteration run are never written: keep only the reached ones.
    reached = [(int(i), snaps[k].copy()) for k, i in enumerate(snap_its) if i <= iterations]
    return _LevelRun(
        xf,
        int(iterations),
        bool(converged),
        energies[:n_rec].copy(),
        energy_its[:n_rec].copy(),
        reached,
    )


def active_contour(
    image: NDArray[np.generic],
    init: ArrayLike,
    *,
    alpha: float = 0.3,
    beta: float = 5.0,
    gamma: float = 1.0,
    lam: float = 1.0,
    sigma_px: float = 1.5,
    eps: float = 0.1,
    external: ExternalMode = "edge",
    edge_weight: float = 1.0,
    balloon: float = 0.0,
    stop_k: float = 0.3,
    gvf_iterations: int = 80,
    n_points: int | None = None,
    max_num_iter: int = 1000,
    max_px_move: float = 0.05,
    max_step_px: float = 1.0,
    resample_every: int = 10,
    pyramid_levels: int = 0,
    roi_margin_px: float | None = 16.0,
    snapshot_at: Sequence[int] = (),
    progress: Progress | None = None,
) -> SnakeResult:
    """Fit a closed active contour to an image (chapter eqs. 6-11; Kass et al. 1988).

    Parameters
    ----------
    image : ndarray of shape (H, W) or (H, W, 3)
        Grey or RGB image, uint8/uint16 or float in [0, 1].
    init : array_like of shape (N, 2)
        Initial closed contour, ``(x, y)`` pixels (see :func:`~vision.segmentation.circle_contour`,
        :func:`~vision.segmentation.box_contour`, :func:`~vision.segmentation.blob_contour`).
    alpha : float
        Tension (eq. 9), >= 0; on its own it shrinks the contour.
    beta : float
        Rigidity (eq. 9), >= 0; resists bending.
    gamma : float
        Viscosity, > 0: the inverse time step of the semi-implicit scheme.
    lam, sigma_px, eps : float
        ``lambda``, ``sigma`` and the division guard of the edge energy (eq. 11).
    external : {"edge", "gvf"}
        Force field: ``-grad E_img`` of eq. 11 (default) or gradient vector flow.
    edge_weight : float
        Factor on that force, >= 0.
    balloon : float
        Pressure along the outward normal (negative shrinks), in pixels per iteration times
        ``gamma``, scaled down on edges by ``1 / (1 + (g_hat / stop_k)^2)``.  0 disables it.
    stop_k : float
        Edge strength (units of the image's 99th-percentile gradient) halving the balloon.
    gvf_iterations : int
        ``external="gvf"``: diffusion iterations; the capture range grows with their square
        root (about 8 px for the default 80).
    n_points : int or None
        Points of the snake; None keeps ``len(init)``.  The init is resampled by arc length.
    max_num_iter : int
        Iteration limit per pyramid level.
    max_px_move : float
        Convergence: mean movement per iteration (pixels of the current level) below this.
    max_step_px : float
        Largest movement of one point in one iteration (keeps the explicit force stable).
    resample_every : int
        Arc-length resampling and convergence-test period, iterations.
    pyramid_levels : int
        Coarse-to-fine levels (0: full resolution only); see :mod:`vision.segmentation.pyramid`.
    roi_margin_px : float or None
        When the snake cannot grow (``balloon <= 0``), the image forces are computed only on
        the bounding box of ``init`` grown by this margin, and the points are kept inside it;
        a shrinking snake never needs more.  None (or ``balloon > 0``): the whole image.
    snapshot_at : sequence of int
        Iterations (of the finest level) at which to keep a copy of the contour.
    progress : callable(fraction, message) or None
        Called after each pyramid level.

    Returns
    -------
    SnakeResult

    Raises
    ------
    ImageError
        Wrong dtype or shape, NaN, an empty or tiny image.
    ValueError
        A contour outside the image or with too few points; a non-positive parameter.

    References
    ----------
    M. Kass, A. Witkin, D. Terzopoulos, "Snakes: active contour models", IJCV 1 (1988).
    L. D. Cohen, "On active contour models and balloons", CVGIP: Image Understanding 53 (1991).

    Examples
    --------
    >>> import numpy as np
    >>> from vision.segmentation import active_contour, circle_contour
    >>> yy, xx = np.mgrid[:120, :120]
    >>> img = ((xx - 60) ** 2 + (yy - 60) ** 2 < 30**2).astype(np.float64)
    >>> res = active_contour(img, circle_contour((60, 60), 45), balloon=-0.6)
    >>> bool(res.converged), round(float(np.hypot(*(res.contour - 60).T).mean()))
    (True, 30)
    """
    img = check_image(image)
    c0 = check_contour(init, img.shape, "init")
    alpha = check_nonnegative(alpha, "alpha")
    beta = check_nonnegative(beta, "beta")
    gamma = check_positive(gamma, "gamma")
    edge_weight = check_nonnegative(edge_weight, "edge_weight")
    balloon = float(balloon)
    if not np.isfinite(balloon):
        raise ValueError(f"balloon must be a finite number, got {balloon!r}")
    n = check_int(len(c0) if n_points is None else n_points, "n_points", minimum=5)
    max_num_iter = check_int(max_num_iter, "max_num_iter", minimum=1)
    max_px_move = check_positive(max_px_move, "max_px_move")
    max_step_px = check_positive(max_step_px, "max_step_px")
    resample_every = check_int(resample_every, "resample_every", minimum=1)
    sigma_px = check_positive(sigma_px, "sigma_px")
    offset = np.zeros(2)
    if roi_margin_px is not None and balloon <= 0.0:
        margin = check_nonnegative(roi_margin_px, "roi_margin_px")
        (x0, y0), (x1, y1) = c0.min(axis=0) - margin, c0.max(axis=0) + margin
        x0, y0 = max(int(np.floor(x0)), 0), max(int(np.floor(y0)), 0)
        x1 = min(int(np.ceil(x1)) + 1, img.shape[1])
        y1 = min(int(np.ceil(y1)) + 1, img.shape[0])
        work = np.ascontiguousarray(img[y0:y1, x0:x1])
        offset = np.array([x0, y0], dtype=np.float64)
    else:
        work = img
    levels = gaussian_pyramid(work, check_int(pyramid_levels, "pyramid_levels", minimum=0))
    snaps_wanted = frozenset(check_int(int(s), "snapshot_at", minimum=0) for s in snapshot_at)

    x = resample_closed(c0 - offset, n) / float(2 ** (len(levels) - 1))
    total = 0
    run: _LevelRun | None = None
    for lev in range(len(levels) - 1, -1, -1):
        field = external_field(
            levels[lev],
            sigma_px=max(sigma_px / 2**lev, 0.7),
            lam=lam,
            eps=eps,
            mode=external,
            weight=edge_weight,
            stop_k=stop_k,
            gvf_iterations=gvf_iterations,
        )
        done_before = len(levels) - 1 - lev

        def report(it: int, _done: int = done_before, _lev: int = lev) -> None:
            if progress is not None:
                frac = (_done + min(it / max_num_iter, 1.0)) / len(levels)
                progress(frac, f"snake level {_lev}: iteration {it}")

        run = _run_level(
            field,
            x,
            alpha=alpha,
            beta=beta,
            gamma=gamma,
            balloon=balloon,
            max_num_iter=max_num_iter,
            max_px_move=max_px_move,
            max_step_px=max_step_px,
            resample_every=resample_every,
            snapshot_at=snaps_wanted if lev == 0 else frozenset(),
        )
        report(run.iterations)
        total += run.iterations
        x = run.contour * 2.0 if lev > 0 else run.contour
    assert run is not None
    x = x + offset
    if progress is not None:
        progress(1.0, "snake done")
    return SnakeResult(
        contour=x,
        mask=mask_from_contour(x, img.shape),
        iterations=total,
        converged=run.converged,
        energy=run.energy,
        energy_iterations=run.energy_iterations,
        snapshots=tuple((it, c + offset) for it, c in run.snapshots),
    )
