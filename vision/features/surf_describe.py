"""SURF orientation and descriptor from Haar-wavelet responses on the integral image.

Bay, Ess, Tuytelaars and Van Gool, "Speeded-Up Robust Features (SURF)", CVIU 110(3), 2008,
section 4. Scale ``s`` of a keypoint is ``size_px / 20`` (VisionCell's SURF keypoints report
the side of the 20 s descriptor window as ``size_px``, see :func:`vision.features.surf_features`).

- Orientation (section 4.1): Haar responses of side ``4 s`` at the points of a circle of radius
  ``6 s`` sampled every ``s``, weighted by a Gaussian of ``sigma = 2 s``; a window of
  ``pi / 3`` slides around the circle of response directions (5 degree steps) and the longest
  sum vector gives the orientation.
- Descriptor (section 4.2): a ``20 s`` square oriented along the keypoint, split into 4 x 4
  sub-regions of 5 x 5 samples spaced ``s``; Haar responses of side ``2 s`` are rotated into the
  keypoint frame, weighted by a Gaussian centred on the keypoint and summed per sub-region as
  ``(sum dx, sum dy, sum |dx|, sum |dy|)``: 64 values, unit-normalised. The extended variant
  (128) sums ``dx`` and ``|dx|`` separately for ``dy < 0`` and ``dy >= 0`` (and ``dy``, ``|dy|``
  by the sign of ``dx``).

Three choices differ from the paper's text, each measured on the Oxford pairs
(docs/readme/features-surf.md):

- Haar boxes have real-valued centres and sides (``2 s`` exactly, not rounded to even pixels),
  evaluated exactly by bilinear interpolation of the integral image;
- each sample is shared between the two nearest sub-regions along each axis (soft binning);
- the Gaussian weight has ``sigma = 4.5 s`` (:data:`DESCRIPTOR_SIGMA`), not ``3.3 s``.

Haar boxes that would leave the image are shifted inside it (the border responses repeat).
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["describe_integral", "describe_integral_channels", "orientation_integral"]

#: Scale of a keypoint in units of its size_px (size_px = 20 s).
WINDOW_IN_S = 20.0
_ORI_RADIUS = 6  # circle radius in s (section 4.1)
_ORI_SIGMA = 2.0  # Gaussian weight in s (section 4.1)
_ORI_WINDOW = math.pi / 3.0
_ORI_STEPS = 72  # window start every 5 degrees
#: Gaussian weight of the descriptor samples, in s. The paper's 3.3 s gives 12-20 % fewer
#: correct matches here (docs/readme/features-surf.md): our detector's s = 1.2 L / 9 is 0.72
#: times the sigma of a Gaussian blob it fires on, so 4.5 s ~ 3.3 blob sigmas.
DESCRIPTOR_SIGMA = 4.5


def _ori_pattern() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    i, j = np.mgrid[-_ORI_RADIUS : _ORI_RADIUS + 1, -_ORI_RADIUS : _ORI_RADIUS + 1]
    keep = i**2 + j**2 < _ORI_RADIUS**2  # 109 points strictly inside the circle
    u, v = j[keep].astype(np.float64), i[keep].astype(np.float64)
    w = np.exp(-(u**2 + v**2) / (2 * _ORI_SIGMA**2))
    return u, v, w


_ORI_U, _ORI_V, _ORI_W = _ori_pattern()
_DESC_T = np.arange(20, dtype=np.float64) - 9.5  # sample offsets along one side, in s
_DESC_W = np.exp(-(_DESC_T[:, None] ** 2 + _DESC_T[None, :] ** 2) / (2 * DESCRIPTOR_SIGMA**2))


@numba.njit(cache=True, inline="always")
def _area(ii, x, y):
    """Integral of the image over [0, x] x [0, y] for real (x, y) in integral-image units: the
    integral of a piecewise-constant image is bilinear inside each pixel, so bilinear
    interpolation of ``ii`` is exact."""
    xi = min(int(x), ii.shape[1] - 2)
    yi = min(int(y), ii.shape[0] - 2)
    fx = x - xi
    fy = y - yi
    top = ii[yi, xi] + fx * (ii[yi, xi + 1] - ii[yi, xi])
    bottom = ii[yi + 1, xi] + fx * (ii[yi + 1, xi + 1] - ii[yi + 1, xi])
    return top + fy * (bottom - top)


@numba.njit(cache=True, inline="always")
def _haar(ii, cx, cy, side):
    """Haar responses (dx, dy) of a ``side`` x ``side`` box (real-valued size and centre, pixel
    centres at integers), shifted inside the image where it would leave it."""
    height = ii.shape[0] - 1
    width = ii.shape[1] - 1
    side = min(side, float(height), float(width))
    h = 0.5 * side
    # pixel (c, r) covers [c - 0.5, c + 0.5]: integral-image coordinates are shifted by 0.5
    x0 = min(max(cx + 0.5 - h, 0.0), width - side)
    y0 = min(max(cy + 0.5 - h, 0.0), height - side)
    x1 = x0 + h
    x2 = x0 + side
    y1 = y0 + h
    y2 = y0 + side
    f00 = _area(ii, x0, y0)
    f10 = _area(ii, x1, y0)
    f20 = _area(ii, x2, y0)
    f01 = _area(ii, x0, y1)
    f21 = _area(ii, x2, y1)
    f02 = _area(ii, x0, y2)
    f12 = _area(ii, x1, y2)
    f22 = _area(ii, x2, y2)
    # right half minus left half; bottom half minus top half
    dx = (f22 - f12 - f20 + f10) - (f12 - f02 - f10 + f00)
    dy = (f22 - f02 - f21 + f01) - (f21 - f01 - f20 + f00)
    return dx, dy


@numba.njit(cache=True)
def _orientations(ii, xs, ys, scales, pu, pv, pw, n_steps, window):
    n = xs.shape[0]
    m = pu.shape[0]
    out = np.zeros(n, dtype=np.float64)
    rx = np.empty(m)
    ry = np.empty(m)
    ang = np.empty(m)
    sa = np.empty(2 * m)
    cx = np.zeros(2 * m + 1)
    cy = np.zeros(2 * m + 1)
    two_pi = 2.0 * math.pi
    for p in range(n):
        s = scales[p]
        side = 4.0 * s  # Haar side 4 s
        for q in range(m):
            dx, dy = _haar(ii, xs[p] + pu[q] * s, ys[p] + pv[q] * s, side)
            rx[q] = pw[q] * dx
            ry[q] = pw[q] * dy
            ang[q] = math.atan2(dy, dx)
        # sliding window over the sorted directions, the list doubled (+2 pi) to wrap around;
        # window sums as differences of running sums
        order = np.argsort(ang)
        for k in range(2 * m):
            q = order[k % m]
            sa[k] = ang[q] + (two_pi if k >= m else 0.0)
            cx[k + 1] = cx[k] + rx[q]
            cy[k + 1] = cy[k] + ry[q]
        best = -1.0
        bx = 0.0
        by = 0.0
        lo = 0
        hi = 0
        for w in range(n_steps):
            a0 = -math.pi + w * two_pi / n_steps
            while lo < m and sa[lo] < a0:
                lo += 1
            hi = max(hi, lo)
            while hi < 2 * m and sa[hi] < a0 + window:
                hi += 1
            sx = cx[hi] - cx[lo]
            sy = cy[hi] - cy[lo]
            mag = sx * sx + sy * sy
            if mag > best:
                best = mag
                bx = sx
                by = sy
        out[p] = math.atan2(by, bx)
    return out


@numba.njit(cache=True, inline="always")
def _accumulate(acc, base, tx, ty, w, extended):
    if extended:
        if ty < 0.0:
            acc[base] += w * tx
            acc[base + 1] += w * abs(tx)
        else:
            acc[base + 2] += w * tx
            acc[base + 3] += w * abs(tx)
        if tx < 0.0:
            acc[base + 4] += w * ty
            acc[base + 5] += w * abs(ty)
        else:
            acc[base + 6] += w * ty
            acc[base + 7] += w * abs(ty)
    else:
        acc[base] += w * tx
        acc[base + 1] += w * ty
        acc[base + 2] += w * abs(tx)
        acc[base + 3] += w * abs(ty)


@numba.njit(cache=True, inline="always")
def _soft_bin(acc, cell, cell_w, b, a, per_cell, tx, ty, extended):
    """Add the sample at grid position (a, b) to the (up to four) sub-regions it is shared
    between (:func:`_cell_weights`)."""
    for kb in range(2):
        wb = cell_w[b, kb]
        if wb == 0.0:
            continue
        for ka in range(2):
            wa = cell_w[a, ka]
            if wa == 0.0:
                continue
            base = (cell[b, kb] * 4 + cell[a, ka]) * per_cell
            _accumulate(acc, base, tx, ty, wa * wb, extended)


@numba.njit(cache=True)
def _descriptors(
    ii, xs, ys, scales, thetas, extended, offs, weights, cell, cell_w, floor, haar_side=2.0
):
    n = xs.shape[0]
    per_cell = 8 if extended else 4
    dim = 16 * per_cell
    out = np.zeros((n, dim), dtype=np.float32)
    acc = np.zeros(dim)
    for p in range(n):
        s = scales[p]
        c = math.cos(thetas[p])
        sn = math.sin(thetas[p])
        side = haar_side * s  # Haar side 2 s (4 s on the coarse grid)
        acc[:] = 0.0
        for b in range(offs.shape[0]):
            v = offs[b]
            for a in range(offs.shape[0]):
                u = offs[a]
                # (u, v) along the keypoint's axes (cos t, sin t) and (-sin t, cos t)
                gx = xs[p] + s * (c * u - sn * v)
                gy = ys[p] + s * (sn * u + c * v)
                dx, dy = _haar(ii, gx, gy, side)
                w = weights[b, a]
                tx = w * (c * dx + sn * dy)
                ty = w * (-sn * dx + c * dy)
                _soft_bin(acc, cell, cell_w, b, a, per_cell, tx, ty, extended)
        norm = 0.0
        for d in range(dim):
            norm += acc[d] * acc[d]
        if norm > floor * floor:  # below: rounding noise of a constant window, left at 0
            inv = 1.0 / math.sqrt(norm)
            for d in range(dim):
                out[p, d] = acc[d] * inv
    return out


@numba.njit(cache=True, inline="always")
def _area_c(ii, x, y, ch):
    """:func:`_area` on channel ``ch`` of a multi-channel integral image (H + 1, W + 1, C)."""
    xi = min(int(x), ii.shape[1] - 2)
    yi = min(int(y), ii.shape[0] - 2)
    fx = x - xi
    fy = y - yi
    top = ii[yi, xi, ch] + fx * (ii[yi, xi + 1, ch] - ii[yi, xi, ch])
    bottom = ii[yi + 1, xi, ch] + fx * (ii[yi + 1, xi + 1, ch] - ii[yi + 1, xi, ch])
    return top + fy * (bottom - top)


@numba.njit(cache=True)
def _descriptors_channels(
    ii, live, xs, ys, scales, thetas, extended, offs, weights, cell, cell_w, floors, haar_side
):
    """:func:`_descriptors` of every channel of ``ii`` (H + 1, W + 1, C) in one pass: the
    sample positions and Haar boxes are computed once per keypoint and read from all channels
    (interleaved, so one cache line serves them all); ``live[p, k]`` false leaves keypoint
    ``p`` of channel ``k`` at 0 without computing it. Same arithmetic per channel as
    :func:`_descriptors` with :func:`_haar`."""
    n = xs.shape[0]
    nc = ii.shape[2]
    per_cell = 8 if extended else 4
    dim = 16 * per_cell
    out = np.zeros((n, nc, dim), dtype=np.float32)
    acc = np.zeros((nc, dim))
    height = ii.shape[0] - 1
    width = ii.shape[1] - 1
    for p in range(n):
        todo = False
        for k in range(nc):
            todo = todo or live[p, k]
        if not todo:
            continue
        s = scales[p]
        c = math.cos(thetas[p])
        sn = math.sin(thetas[p])
        side = min(haar_side * s, float(height), float(width))
        h = 0.5 * side
        acc[:, :] = 0.0
        for b in range(offs.shape[0]):
            v = offs[b]
            for a in range(offs.shape[0]):
                u = offs[a]
                gx = xs[p] + s * (c * u - sn * v)
                gy = ys[p] + s * (sn * u + c * v)
                x0 = min(max(gx + 0.5 - h, 0.0), width - side)
                y0 = min(max(gy + 0.5 - h, 0.0), height - side)
                x1 = x0 + h
                x2 = x0 + side
                y1 = y0 + h
                y2 = y0 + side
                w = weights[b, a]
                for k in range(nc):
                    if not live[p, k]:
                        continue
                    f00 = _area_c(ii, x0, y0, k)
                    f10 = _area_c(ii, x1, y0, k)
                    f20 = _area_c(ii, x2, y0, k)
                    f01 = _area_c(ii, x0, y1, k)
                    f21 = _area_c(ii, x2, y1, k)
                    f02 = _area_c(ii, x0, y2, k)
                    f12 = _area_c(ii, x1, y2, k)
                    f22 = _area_c(ii, x2, y2, k)
                    dx = (f22 - f12 - f20 + f10) - (f12 - f02 - f10 + f00)
                    dy = (f22 - f02 - f21 + f01) - (f21 - f01 - f20 + f00)
                    tx = w * (c * dx + sn * dy)
                    ty = w * (-sn * dx + c * dy)
                    _soft_bin(acc[k], cell, cell_w, b, a, per_cell, tx, ty, extended)
        for k in range(nc):
            if not live[p, k]:
                continue
            norm = 0.0
            for d in range(dim):
                norm += acc[k, d] * acc[k, d]
            if norm > floors[k] * floors[k]:
                inv = 1.0 / math.sqrt(norm)
                for d in range(dim):
                    out[p, k, d] = acc[k, d] * inv
    return out


def _cell_weights(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sub-regions (n, 2) and weights (n, 2) of the samples at positions ``t`` (units of s)
    along a side: each sample is shared between the two nearest sub-region centres by linear
    interpolation (soft binning, as SIFT's histograms do), so a sample drifting across a
    boundary changes the descriptor smoothly; samples outside the outer centres keep only
    their inner share."""
    pos = t / 5.0 + 1.5  # in sub-region units: sub-region k is centred at k
    i0 = np.floor(pos).astype(np.int64)
    frac = pos - i0
    idx = np.c_[i0, i0 + 1]
    w = np.c_[1.0 - frac, frac]
    w[(idx < 0) | (idx > 3)] = 0.0
    return np.clip(idx, 0, 3), w


_CELL, _CELL_W = _cell_weights(_DESC_T)
# Coarse grid: 10 x 10 samples spaced 2 s with Haar boxes of side 4 s, the same 20 s window,
# sub-regions and Gaussian weight: a quarter of the work, for smooth signals (colour ratios).
_COARSE_T = np.arange(10, dtype=np.float64) * 2.0 - 9.0
_COARSE_W = np.exp(-(_COARSE_T[:, None] ** 2 + _COARSE_T[None, :] ** 2) / (2 * DESCRIPTOR_SIGMA**2))
_COARSE_CELL, _COARSE_CELL_W = _cell_weights(_COARSE_T)


def _noise_floor(ii: np.ndarray) -> float:
    """Descriptor length below which the Haar sums are floating-point noise: integral-image
    values are exact to about 1e-16 of their largest magnitude, a Haar response combines 9 of
    them and a descriptor sums 400 weighted responses; 1e-12 of that keeps a wide margin and
    is still far below any real texture (a one-level step gives lengths of order 100)."""
    return 1e-12 * float(np.abs(ii).max()) * float(_DESC_W.sum())


def orientation_integral(ii: np.ndarray, xy: np.ndarray, scales: np.ndarray) -> np.ndarray:
    """Dominant Haar-wavelet orientation (section 4.1) of keypoints at ``xy`` with scales ``s``.

    Returns angles in radians in the image frame (x right, y down), i.e. clockwise on screen;
    negate for :attr:`Keypoints.angle_rad`.
    """
    xy = np.ascontiguousarray(xy, dtype=np.float64).reshape(-1, 2)
    return _orientations(
        ii,
        np.ascontiguousarray(xy[:, 0]),
        np.ascontiguousarray(xy[:, 1]),
        np.ascontiguousarray(scales, dtype=np.float64),
        _ORI_U,
        _ORI_V,
        _ORI_W,
        _ORI_STEPS,
        _ORI_WINDOW,
    )


def describe_integral(
    ii: np.ndarray,
    xy: np.ndarray,
    scales: np.ndarray,
    theta_image: np.ndarray,
    *,
    extended: bool = False,
    coarse: bool = False,
) -> np.ndarray:
    """SURF descriptors (section 4.2) on an integral image, (N, 64) or (N, 128) float32.

    ``theta_image`` is the keypoint orientation in the image frame (clockwise on screen).
    ``coarse`` samples the same window on a 10 x 10 grid spaced ``2 s`` with Haar boxes of
    side ``4 s`` (a quarter of the work; for smooth images such as colour ratios).
    """
    xy = np.ascontiguousarray(xy, dtype=np.float64).reshape(-1, 2)
    if coarse:  # the same window's noise floor, scaled by the coarse grid's total weight
        grid = (_COARSE_T, _COARSE_W, _COARSE_CELL, _COARSE_CELL_W)
        floor, side = _noise_floor(ii) * float(_COARSE_W.sum() / _DESC_W.sum()), 4.0
    else:
        grid, floor, side = (_DESC_T, _DESC_W, _CELL, _CELL_W), _noise_floor(ii), 2.0
    return _descriptors(
        ii,
        np.ascontiguousarray(xy[:, 0]),
        np.ascontiguousarray(xy[:, 1]),
        np.ascontiguousarray(scales, dtype=np.float64),
        np.ascontiguousarray(theta_image, dtype=np.float64),
        bool(extended),
        *grid,
        floor,
        side,
    )


def describe_integral_channels(
    ii: np.ndarray,
    xy: np.ndarray,
    scales: np.ndarray,
    theta_image: np.ndarray,
    *,
    live: np.ndarray | None = None,
    extended: bool = False,
    coarse: bool = False,
) -> np.ndarray:
    """:func:`describe_integral` of every channel of a multi-channel integral image
    ``ii`` (H + 1, W + 1, C) in one pass, (N, C, 64) or (N, C, 128) float32.

    ``live`` (N, C) bool, default all true: where false the descriptor is left at 0 and not
    computed. Each channel's result equals :func:`describe_integral` of that channel's
    integral image.
    """
    ii = np.ascontiguousarray(ii, dtype=np.float64)
    if ii.ndim != 3:
        raise ValueError(f"ii must have shape (H + 1, W + 1, C), got {ii.shape}")
    xy = np.ascontiguousarray(xy, dtype=np.float64).reshape(-1, 2)
    n, nc = len(xy), ii.shape[2]
    live = np.ones((n, nc), bool) if live is None else np.ascontiguousarray(live, dtype=bool)
    if live.shape != (n, nc):
        raise ValueError(f"live must have shape {(n, nc)}, got {live.shape}")
    offs, w, cell, cell_w = (
        (_COARSE_T, _COARSE_W, _COARSE_CELL, _COARSE_CELL_W)
        if coarse
        else (_DESC_T, _DESC_W, _CELL, _CELL_W)
    )
    share = float(w.sum() / _DESC_W.sum())
    floors = np.array([_noise_floor(ii[..., k]) * share for k in range(nc)], np.float64)
    return _descriptors_channels(
        ii,
        live,
        np.ascontiguousarray(xy[:, 0]),
        np.ascontiguousarray(xy[:, 1]),
        np.ascontiguousarray(scales, dtype=np.float64),
        np.ascontiguousarray(theta_image, dtype=np.float64),
        bool(extended),
        offs,
        w,
        cell,
        cell_w,
        floors,
        4.0 if coarse else 2.0,
    )
