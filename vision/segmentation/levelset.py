"""Region-based level set: Chan-Vese on grey and colour images (the chapter's Figure 3).

The two-phase piecewise-constant Mumford-Shah energy of Chan and Vese (2001), in its
vector-valued form for colour images (Chan, Sandberg and Vese 2000), is

    E(Sigma, c1, c2) = mu Per(Sigma)
                     + lambda1 / C sum_c int_Sigma   (I_c - c1_c)^2
                     + lambda2 / C sum_c int_Sigma^c (I_c - c2_c)^2,

with ``Sigma`` the inside region, ``C`` the number of channels and ``c1``, ``c2`` the mean
colours inside and outside.  Two solvers minimise it:

``method="threshold"`` (default, fast)
    Threshold dynamics of Esedoglu and Tsai (2006): with ``u`` the indicator of ``Sigma`` and
    ``G`` a Gaussian of standard deviation ``sigma_px`` (heat kernel of time
    ``dt = sigma_px^2 / 2``), ``Per(Sigma) ~ sqrt(pi / dt) int (1 - u) G * u``.  Linearising
    this concave term at ``u_k`` and minimising over indicators gives the update

        u_{k+1} = [ G * u_k > 1/2 + sqrt(dt / pi) / (2 mu) * (D1 - D2) ],

    ``D1 = lambda1 |I - c1|^2 / C``, ``D2 = lambda2 |I - c2|^2 / C``; each step decreases the
    approximate energy, and the front may move many pixels per step.  One Gaussian blur
    (``cv2.GaussianBlur``) and a few array operations per iteration.

``method="pde"``
    The level-set evolution of Chan and Vese (2001): ``phi`` a signed distance, positive
    inside, ``dphi/dt = delta_eps(phi) (mu kappa - D1 + D2)`` with ``kappa`` the curvature of
    the level lines and ``delta_eps`` the regularised Dirac (``eps`` = 1), discretised by their
    semi-implicit scheme (their eq. 9; one Gauss-Seidel sweep per iteration, compiled with
    Numba in :func:`vision.segmentation._kernels.chan_vese_sweep`), ``phi`` re-initialised to a
    signed distance (``cv2.distanceTransform``) every ``reinit_every`` sweeps.  The front moves
    at most ``step_px`` per sweep, so the evolution is gradual, as in the chapter's Figure 3.

``local_radius_px`` switches either solver to the localised energy of Lankton and Tannenbaum
(2008): ``c1`` and ``c2`` become per-pixel means over a Gaussian window ``K`` around each pixel,
``u_in = K * (u I) / K * u`` and ``u_out = K * ((1 - u) I) / K * (1 - u)`` (two blurs of the
whole image per iteration), and ``D1``, ``D2`` compare each pixel with its own window's means,
so the front separates the object from what is near its boundary instead of the image's two
dominant classes.  Like every local model it sees only that far: the initial contour must lie
within about a window of the object's boundary.

Images are float in [0, 1] (uint8 and uint16 are scaled), so ``mu`` is in units of squared
intensity times pixels.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from vision.errors import ImageError
from vision.segmentation.contours import circle_contour, contour_from_mask, mask_from_contour
from vision.segmentation.pyramid import gaussian_pyramid, upsample_mask
from vision.segmentation.validation import (
    check_contour,
    check_image,
    check_int,
    check_positive,
)

__all__ = ["LevelSetResult", "chan_vese", "region_contours"]

Progress = Callable[[float, str], None]


@dataclass(frozen=True)
class LevelSetResult:
    """Outcome of :func:`chan_vese`.

    Attributes
    ----------
    mask : ndarray of shape (H, W), bool
        The inside region ``Sigma`` (``phi > 0``).
    contour : ndarray of shape (N, 2), float64
        Outer boundary of the largest connected inside region, ``(x, y)`` pixels (centres of
        its boundary pixels); shape (0, 2) when the region is empty.
    iterations : int
        Iterations run, summed over the pyramid levels.
    converged : bool
        Whether the region stopped changing (on the finest level) before ``max_num_iter``.
    energy : ndarray of shape (K,), float64
        The Chan-Vese energy at each recorded iteration of the finest level (for
        ``"threshold"`` its heat-content approximation, the quantity that solver decreases).
    energy_iterations : ndarray of shape (K,), int64
        The iteration each ``energy`` entry belongs to.
    mean_inside, mean_outside : ndarray of shape (C,)
        ``c1`` and ``c2``, per channel, in [0, 1].
    snapshots : tuple of (int, tuple of ndarray of shape (N_i, 2))
        For each iteration in ``snapshot_at``: the boundaries of all inside regions then.
    """

    mask: NDArray[np.bool_]
    contour: NDArray[np.float64]
    iterations: int
    converged: bool
    energy: NDArray[np.float64]
    energy_iterations: NDArray[np.int64]
    mean_inside: NDArray[np.float64]
    mean_outside: NDArray[np.float64]
    snapshots: tuple[tuple[int, tuple[NDArray[np.float64], ...]], ...] = ()


def region_contours(mask: ArrayLike) -> tuple[NDArray[np.float64], ...]:
    """Boundaries of all connected regions of ``mask`` (outer and hole boundaries), ``(x, y)``."""
    m = np.asarray(mask).astype(np.uint8)
    found, _ = cv2.findContours(m, cv2.RETR_LIST, cv2.CHAIN_APPROX_NONE)
    return tuple(c[:, 0, :].astype(np.float64) for c in found)


@dataclass
class _Data:
    """The image and the sums every iteration reuses."""

    f: NDArray[np.float32]  # (H, W, C)
    sq: NDArray[np.float32]  # (H, W): |f|^2 / C
    fsq: NDArray[np.float32]  # (H, W, C + 1): f and sq stacked, summed by one cv2.mean
    total: NDArray[np.float64]  # (C,): sum of f over the image
    sq_total: float  # sum of |f|^2 / C over the image
    lambda1: float
    lambda2: float
    blurred: NDArray[np.float32] | None = None  # K * f for the local model, cached
    blur_sigma: float = 0.0

    @classmethod
    def of(cls, img: NDArray[np.float32], lambda1: float, lambda2: float) -> _Data:
        f = img if img.ndim == 3 else img[:, :, None]
        c = f.shape[2]
        sq = (np.einsum("ijc,ijc->ij", f, f) / c).astype(np.float32)
        total = f.reshape(-1, c).sum(axis=0, dtype=np.float64)
        fsq = np.ascontiguousarray(np.dstack([f, sq]))
        return cls(f, sq, fsq, total, float(sq.sum(dtype=np.float64)), lambda1, lambda2)

    def stats(
        self, u8: NDArray[np.uint8]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
        """``c1``, ``c2`` (mean colour inside and outside) and ``int D1 + int D2`` for ``u8``.

        The fitting energy follows from sums alone: ``sum_in |f - c1|^2 = sum_in |f|^2 -
        |sum_in f|^2 / n_in`` (and likewise outside), so no per-pixel pass is needed.
        """
        c = self.f.shape[2]
        n_all = u8.size
        n_in = int(cv2.countNonZero(u8))
        n_out = n_all - n_in
        if n_in:
            sums = np.asarray(cv2.mean(self.fsq, mask=u8)[: c + 1]) * n_in
            s_in, q_in = sums[:c], float(sums[c])
        else:
            s_in, q_in = np.zeros(c), 0.0
        s_out = self.total - s_in
        q_out = self.sq_total - q_in
        c1 = s_in / max(n_in, 1)
        c2 = s_out / max(n_out, 1)
        e_in = q_in - float(s_in @ s_in) / (c * n_in) if n_in else 0.0
        e_out = q_out - float(s_out @ s_out) / (c * n_out) if n_out else 0.0
        return c1, c2, self.lambda1 * e_in + self.lambda2 * e_out

    def difference(self, c1: NDArray[np.float64], c2: NDArray[np.float64]) -> NDArray[np.float32]:
        """``D1 - D2`` per pixel: lambda1 |f - c1|^2 / C - lambda2 |f - c2|^2 / C."""
        c = self.f.shape[2]
        l1, l2 = self.lambda1, self.lambda2
        w = (-2.0 / c) * (l1 * c1 - l2 * c2)
        b = (l1 * float(c1 @ c1) - l2 * float(c2 @ c2)) / c
        lin = cv2.transform(self.f, w.reshape(1, c).astype(np.float32))
        lin = lin.reshape(self.f.shape[:2]) + np.float32(b)
        if l1 != l2:
            lin += np.float32(l1 - l2) * self.sq
        return lin

    def local_terms(
        self,
        u8: NDArray[np.uint8],
        sigma: float,
        c1: NDArray[np.float64],
        c2: NDArray[np.float64],
    ) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        """Localised ``D1``, ``D2`` (Lankton and Tannenbaum 2008) per pixel.

        ``u_in(x) = (K * (u f))(x) / (K * u)(x)`` and ``u_out(x) = (K * ((1 - u) f))(x) /
        (K * (1 - u))(x)``, ``K`` a Gaussian window of standard deviation ``sigma``; then
        ``D1 = lambda1 |f - u_in|^2 / C`` and ``D2 = lambda2 |f - u_out|^2 / C``.  A window
        with (almost) no pixel of one phase falls back to that phase's global mean (``c1`` or
        ``c2``): the ratio is regularised as ``(K*(u f) + e c1) / (K*u + e)``, ``e = 1e-3``.
        """
        c = self.f.shape[2]
        if self.blurred is None or self.blur_sigma != sigma:
            self.blurred = _blur(self.f, sigma)
            self.blur_sigma = sigma
        # f and 1 masked by u, stacked: one blur (at most 4 channels) gives K*(u f) and K*u.
        uf1 = np.empty((*self.f.shape[:2], c + 1), np.float32)
        uf1[:, :, :c] = self.f
        uf1[:, :, c] = 1.0
        uf1 *= u8[:, :, None]
        k = (
            _blur(uf1, sigma)
            if c + 1 <= 4
            else np.dstack([_blur(uf1[:, :, :c], sigma), _blur(uf1[:, :, c], sigma)])
        )
        k_uf, k_u = k[:, :, :c], k[:, :, c:]
        eps = np.float32(1e-3)
        # BORDER_REFLECT: the blur of an all-ones image is one, so K*(1-u) = 1 - K*u.
        u_in = (k_uf + eps * c1.astype(np.float32)) / (k_u + eps)
        u_out = (self.blurred - k_uf + eps * c2.astype(np.float32)) / (np.float32(1.0) - k_u + eps)
        u_in -= self.f
        u_out -= self.f
        d1 = np.einsum("ijc,ijc->ij", u_in, u_in)
        d2 = np.einsum("ijc,ijc->ij", u_out, u_out)
        return (
            (np.float32(self.lambda1 / c) * d1).astype(np.float32),
            (np.float32(self.lambda2 / c) * d2).astype(np.float32),
        )


def _blur(a: NDArray[np.float32], sigma: float) -> NDArray[np.float32]:
    """Gaussian blur (std ``sigma``) keeping the channel axis, reflected borders."""
    out = cv2.GaussianBlur(a, (0, 0), sigma, borderType=cv2.BORDER_REFLECT)
    return np.asarray(out, dtype=np.float32).reshape(a.shape)


@dataclass
class _Run:
    mask: NDArray[np.bool_]
    iterations: int
    converged: bool
    energy: list[float]
    energy_iterations: list[int]
    c1: NDArray[np.float64]
    c2: NDArray[np.float64]
    snapshots: list[tuple[int, tuple[NDArray[np.float64], ...]]]


def _threshold_dynamics(
    data: _Data,
    mask: NDArray[np.bool_],
    *,
    mu: float,
    sigma_px: float,
    sigma_start_px: float,
    band_px: int | None,
    max_num_iter: int,
    tol_px: int,
    local_sigma_px: float | None,
    snapshot_at: frozenset[int],
    progress: Callable[[int], None] | None,
) -> _Run:
    kernel = (
        None
        if band_px is None
        else cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * band_px + 1, 2 * band_px + 1))
    )
    sigma = max(sigma_start_px, sigma_px)
    u = mask.astype(np.uint8)
    prev2: NDArray[np.uint8] | None = None
    energies: list[float] = []
    its: list[int] = []
    snaps = [(0, region_contours(u))] if 0 in snapshot_at else []
    converged = False
    c1 = c2 = np.zeros(data.f.shape[2])
    it = 0
    for it in range(1, max_num_iter + 1):
        dt = 0.5 * sigma * sigma  # heat-kernel time of a Gaussian of std sigma
        kappa = math.sqrt(dt / math.pi) / (2.0 * mu)
        c1, c2, e_data = data.stats(u)
        v = cv2.GaussianBlur(u.astype(np.float32), (0, 0), sigma, borderType=cv2.BORDER_REFLECT)
        if local_sigma_px is None:
            diff = data.difference(c1, c2)
        else:
            # Localised fitting: the energy recorded is the pointwise local fit, sum of D1
            # inside and D2 outside with each pixel's own window means.
            d1, d2 = data.local_terms(u, local_sigma_px, c1, c2)
            diff = d1 - d2
            e_data = float(d2.sum(dtype=np.float64)) + float(
                cv2.mean(diff, mask=u)[0]
            ) * cv2.countNonZero(u)
        # Heat-content perimeter: int (1 - u) G*u = int G*u - int u G*u.
        n_in = cv2.countNonZero(u)
        overlap = float(v.sum(dtype=np.float64)) - float(cv2.mean(v, mask=u)[0]) * n_in
        energies.append(mu * math.sqrt(math.pi / dt) * overlap + e_data)
        its.append(it - 1)
        # Minimiser of the linearised energy: inside where G*u - 1/2 beats the data term.
        new = (v > np.float32(0.5) + np.float32(kappa) * diff).astype(np.uint8)
        if kernel is not None:
            # Local evolution: only pixels within band_px of the front may change, so the
            # region grows or shrinks from its boundary and no far region appears at once.
            # Minimising over this subset still cannot raise the energy (u_k is in it).
            band = cv2.dilate(u, kernel) - cv2.erode(u, kernel)
            new = np.where(band.astype(bool), new, u)
        changed = int(cv2.countNonZero(cv2.absdiff(new, u)))
        cycled = prev2 is not None and not np.any(cv2.absdiff(new, prev2))
        prev2, u = u, new
        if it in snapshot_at:
            snaps.append((it, region_contours(u)))
        if progress is not None:
            progress(it)
        if changed <= tol_px or cycled:
            if sigma <= sigma_px:
                converged = True
                break
            # Continuation: a front whose per-step move is under half a pixel is pinned
            # to the grid; larger steps first, then the requested scale.
            sigma = max(sigma_px, 0.7 * sigma)
            prev2 = None
    return _Run(u.astype(bool), it, converged, energies, its, c1, c2, snaps)


def _signed_distance(mask: NDArray[np.bool_]) -> NDArray[np.float32]:
    """Signed distance to the region boundary, positive inside, half-pixel offset."""
    m = mask.astype(np.uint8)
    d_in = cv2.distanceTransform(m, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    d_out = cv2.distanceTransform(1 - m, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    return (d_in - d_out - np.float32(0.5) * (2 * m.astype(np.float32) - 1)).astype(np.float32)


def _pde(
    data: _Data,
    mask: NDArray[np.bool_],
    *,
    mu: float,
    step_px: float,
    band_px: int | None,
    reinit_every: int,
    max_num_iter: int,
    tol_px: int,
    check_every: int,
    local_sigma_px: float | None,
    snapshot_at: frozenset[int],
    progress: Callable[[int], None] | None,
) -> _Run:
    from vision.segmentation import _kernels  # Numba: load only when this solver runs

    phi = _signed_distance(mask).astype(np.float64)
    # Between re-initialisations the front may travel step_px per iteration: the band must
    # hold it, else the front would stall against frozen values.
    band = -1.0 if band_px is None else float(band_px + step_px * reinit_every)
    energies: list[float] = []
    its: list[int] = []
    snaps = [(0, region_contours(phi > 0))] if 0 in snapshot_at else []
    last = phi > 0
    converged = False
    c1 = c2 = np.zeros(data.f.shape[2])
    it = 0
    for it in range(1, max_num_iter + 1):
        u8 = (phi > 0).astype(np.uint8)
        c1, c2, _ = data.stats(u8)
        if local_sigma_px is None:
            diff = data.difference(c1, c2).astype(np.float64)
        else:
            d1, d2 = data.local_terms(u8, local_sigma_px, c1, c2)
            diff = (d1 - d2).astype(np.float64)
        # Time step: a typical data term (the median near the front) moves the front, where
        # delta = 1/pi, by step_px; every change is clipped to step_px, and the semi-implicit
        # curvature term is stable at any step.
        near = np.abs(phi) <= 1.0
        scale = float(np.median(np.abs(diff[near]))) if near.any() else float(np.abs(diff).max())
        dt = step_px * math.pi / max(scale, 1e-12)
        _kernels.chan_vese_sweep(phi, diff, mu, dt, band, step_px)
        if it % reinit_every == 0:
            phi = _signed_distance(phi > 0).astype(np.float64)
        if it in snapshot_at:
            snaps.append((it, region_contours(phi > 0)))
        if it % check_every == 0 or it == max_num_iter:
            now = phi > 0
            contours = region_contours(now)
            length = float(sum(cv2.arcLength(c.astype(np.float32), True) for c in contours))
            now8 = now.astype(np.uint8)
            if local_sigma_px is None:
                e_data = data.stats(now8)[2]
            else:
                d1, d2 = data.local_terms(now8, local_sigma_px, *data.stats(now8)[:2])
                e_data = float(d2.sum(dtype=np.float64)) + float((d1 - d2)[now].sum())
            energies.append(mu * length + e_data)
            its.append(it)
            if progress is not None:
                progress(it)
            if int(np.count_nonzero(now != last)) <= tol_px:
                converged = True
                break
            last = now
    return _Run(phi > 0, it, converged, energies, its, c1, c2, snaps)


def chan_vese(
    image: NDArray[np.generic],
    init: ArrayLike | None = None,
    *,
    mu: float | None = None,
    lambda1: float = 1.0,
    lambda2: float = 1.0,
    method: Literal["threshold", "pde"] = "threshold",
    sigma_px: float = 3.0,
    sigma_start_px: float | None = None,
    band_px: int | None = 1,
    step_px: float = 1.0,
    reinit_every: int = 10,
    max_num_iter: int = 500,
    tol_px: int = 0,
    check_every: int = 10,
    pyramid_levels: int = 0,
    local_radius_px: float | None = None,
    snapshot_at: Sequence[int] = (),
    progress: Progress | None = None,
) -> LevelSetResult:
    """Two-phase Chan-Vese segmentation of a grey or colour image (Figure 3 of the chapter).

    Parameters
    ----------
    image : ndarray of shape (H, W) or (H, W, 3)
        Grey or RGB; uint8/uint16 or float in [0, 1].  Colour uses all channels
        (Chan-Sandberg-Vese), not a grey conversion.
    init : ndarray of shape (H, W) bool, or (N, 2) contour, or None
        Initial inside region: a mask, a closed ``(x, y)`` contour (filled), or None for a
        centred disc of a quarter of the smaller side.
    mu : float or None
        Weight of the perimeter (> 0); larger gives smoother, rounder regions.  None: 0.5 for
        ``"threshold"``, 0.05 for ``"pde"`` (whose front moves about ``|D1 - D2| / (4 mu)``
        pixels per sweep, so a large ``mu`` makes it crawl).
    lambda1, lambda2 : float
        Weights of the inside and outside fitting terms (> 0).
    method : {"threshold", "pde"}
        Threshold dynamics (fast) or the level-set PDE; see the module docstring.
    sigma_px : float
        ``"threshold"``: the diffusion's standard deviation, pixels.  One step moves the front
        by about ``sigma_px^2 / 2 * |D1 - D2| / mu``; below half a pixel it cannot move at all
        (pinning on the pixel grid, Esedoglu and Tsai 2006), so weak contrast needs larger
        steps: see ``sigma_start_px``.
    sigma_start_px : float or None
        ``"threshold"``: start with this larger diffusion and shrink it by 0.7 each time the
        region stops changing, down to ``sigma_px`` (continuation against pinning).  None:
        ``2 * sigma_px``.
    band_px : int or None
        Local evolution: only pixels within this distance of the current boundary may change
        in one iteration (a narrow band), so the region evolves from its initial contour, as
        an active contour does, instead of jumping to the global two-phase partition of the
        image; None lets every pixel change (the global behaviour of the original methods,
        which also nucleates interior regions).  ``"pde"`` widens the band by
        ``step_px * reinit_every`` so that the front can travel between re-initialisations.
    step_px : float
        ``"pde"``: largest front movement per iteration, pixels.
    reinit_every : int
        ``"pde"``: iterations between re-initialisations of ``phi``.
    max_num_iter : int
        Iteration limit per pyramid level.
    tol_px : int
        Converged when at most this many pixels change (``"threshold"``: per iteration, or a
        two-cycle; ``"pde"``: between checks).
    check_every : int
        ``"pde"``: iterations between energy records and convergence checks.
    pyramid_levels : int
        Coarse-to-fine levels; the coarse result, upsampled, initialises the next level.
    local_radius_px : float or None
        Localised region model (Lankton and Tannenbaum 2008): the inside and outside means
        are computed per pixel ``x`` over a Gaussian window of standard deviation
        ``local_radius_px`` around it, ``u_in(x) = K * (H f) / K * H`` (likewise outside),
        and the force at ``x`` compares ``f(x)`` with ``u_in(x)`` and ``u_out(x)``, so the
        contour separates the object from what is near its boundary rather than from the
        whole image (a window without pixels of one phase falls back to that phase's global
        mean).  Halved on each pyramid level.  None (default): the global two-phase model.
        ``energy`` then records the pointwise local fit, which the solvers are not proven to
        decrease.
    snapshot_at : sequence of int
        Iterations (finest level) whose region boundaries are kept, as in Figure 3.
    progress : callable(fraction, message) or None

    Returns
    -------
    LevelSetResult

    References
    ----------
    T. F. Chan, L. A. Vese, "Active contours without edges", IEEE TIP 10(2), 2001.
    T. F. Chan, B. Y. Sandberg, L. A. Vese, "Active contours without edges for vector-valued
    images", JVCIR 11, 2000.
    S. Esedoglu, Y.-H. R. Tsai, "Threshold dynamics for the piecewise constant Mumford-Shah
    functional", J. Comput. Phys. 211, 2006.
    S. Lankton, A. Tannenbaum, "Localizing region-based active contours", IEEE TIP 17(11),
    2008.

    Examples
    --------
    >>> import numpy as np
    >>> from vision.segmentation import chan_vese
    >>> yy, xx = np.mgrid[:64, :64]
    >>> img = ((xx - 32) ** 2 + (yy - 30) ** 2 < 15**2).astype(np.float32)
    >>> res = chan_vese(img)
    >>> bool(res.converged), int(res.mask.sum()) in range(650, 760)
    (True, True)
    """
    img = check_image(image)
    h, w = img.shape[:2]
    if init is None:
        mask0 = mask_from_contour(
            circle_contour(((w - 1) / 2, (h - 1) / 2), min(h, w) / 4), img.shape
        )
    else:
        arr = np.asarray(init)
        if arr.ndim == 2 and arr.shape == (h, w):
            if arr.dtype != bool and not np.isin(arr, (0, 1)).all():
                raise ValueError(
                    f"init mask must be boolean or 0/1, got values of dtype {arr.dtype}"
                )
            mask0 = arr.astype(bool)
        elif arr.ndim == 2 and arr.shape[1] == 2:
            mask0 = mask_from_contour(
                check_contour(arr, img.shape, "init", min_points=3), img.shape
            )
        else:
            raise ValueError(
                f"init must be a ({h}, {w}) mask or an (N, 2) contour, got shape {arr.shape}"
            )
    if not mask0.any() or mask0.all():
        raise ValueError("init must leave pixels both inside and outside the region")
    if method not in ("threshold", "pde"):
        raise ValueError(f"method must be 'threshold' or 'pde', got {method!r}")
    mu = (0.5 if method == "threshold" else 0.05) if mu is None else check_positive(mu, "mu")
    lambda1 = check_positive(lambda1, "lambda1")
    lambda2 = check_positive(lambda2, "lambda2")
    sigma_px = check_positive(sigma_px, "sigma_px")
    sigma_start_px = (
        2.0 * sigma_px
        if sigma_start_px is None
        else check_positive(sigma_start_px, "sigma_start_px")
    )
    if band_px is not None:
        band_px = check_int(band_px, "band_px", minimum=1)
    step_px = check_positive(step_px, "step_px")
    reinit_every = check_int(reinit_every, "reinit_every", minimum=1)
    max_num_iter = check_int(max_num_iter, "max_num_iter", minimum=1)
    tol_px = check_int(tol_px, "tol_px", minimum=0)
    check_every = check_int(check_every, "check_every", minimum=1)
    if local_radius_px is not None:
        local_radius_px = check_positive(local_radius_px, "local_radius_px")
    levels = gaussian_pyramid(img, check_int(pyramid_levels, "pyramid_levels", minimum=0))
    snaps_wanted = frozenset(check_int(int(s), "snapshot_at", minimum=0) for s in snapshot_at)

    masks = [mask0]
    for level_img in levels[1:]:
        masks.append(
            cv2.resize(
                masks[-1].astype(np.uint8),
                (level_img.shape[1], level_img.shape[0]),
                interpolation=cv2.INTER_AREA,
            )
            > 0
        )
    mask = masks[-1]
    if not mask.any():
        raise ImageError(
            f"init region vanishes at pyramid level {len(levels) - 1}; use fewer pyramid_levels"
        )
    total = 0
    run: _Run | None = None
    for lev in range(len(levels) - 1, -1, -1):
        data = _Data.of(levels[lev], lambda1, lambda2)
        done_before = len(levels) - 1 - lev

        def report(it: int, _done: int = done_before, _lev: int = lev) -> None:
            if progress is not None:
                frac = (_done + min(it / max_num_iter, 1.0)) / len(levels)
                progress(frac, f"chan-vese level {_lev}: iteration {it}")

        snaps = snaps_wanted if lev == 0 else frozenset()
        local_sigma = None if local_radius_px is None else max(local_radius_px / 2**lev, 1.0)
        if method == "threshold":
            run = _threshold_dynamics(
                data,
                mask,
                mu=mu,
                sigma_px=max(sigma_px / 2**lev, 1.0),
                sigma_start_px=max(sigma_start_px / 2**lev, 1.0),
                band_px=band_px,
                max_num_iter=max_num_iter,
                tol_px=tol_px,
                local_sigma_px=local_sigma,
                snapshot_at=snaps,
                progress=report,
            )
        else:
            run = _pde(
                data,
                mask,
                mu=mu,
                step_px=step_px,
                band_px=band_px,
                reinit_every=reinit_every,
                max_num_iter=max_num_iter,
                tol_px=tol_px,
                check_every=check_every,
                local_sigma_px=local_sigma,
                snapshot_at=snaps,
                progress=report,
            )
        total += run.iterations
        mask = upsample_mask(run.mask, levels[lev - 1].shape) if lev > 0 else run.mask
    assert run is not None
    if progress is not None:
        progress(1.0, "chan-vese done")
    return LevelSetResult(
        mask=mask,
        contour=contour_from_mask(mask),
        iterations=total,
        converged=run.converged,
        energy=np.asarray(run.energy, dtype=np.float64),
        energy_iterations=np.asarray(run.energy_iterations, dtype=np.int64),
        mean_inside=np.asarray(run.c1, dtype=np.float64),
        mean_outside=np.asarray(run.c2, dtype=np.float64),
        snapshots=tuple(run.snapshots),
    )
