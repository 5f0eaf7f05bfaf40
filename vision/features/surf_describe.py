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
  keypoint frame, weighted by a Gaussian of ``sigma = 3.3 s`` centred on the keypoint and summed
  per sub-region as ``(sum dx, sum dy, sum |dx|, sum |dy|)``: 64 values, unit-normalised. The
  extended variant (128) sums ``dx`` and ``|dx|`` separately for ``dy < 0`` and ``dy >= 0``
  (and ``dy``, ``|dy|`` by the sign of ``dx``).

Haar boxes that would leave the image are shifted inside it (the border responses repeat).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from vision.features.surf_detect import _box

__all__ = ["describe_integral", "orientation_integral"]

#: Scale of a keypoint in units of its size_px (size_px = 20 s).
WINDOW_IN_S = 20.0
_ORI_RADIUS = 6  # circle radius in s (section 4.1)
_ORI_SIGMA = 2.0  # Gaussian weight in s (section 4.1)
_ORI_WINDOW = math.pi / 3.0
_ORI_STEPS = 72  # window start every 5 degrees
_DESC_SIGMA = 3.3  # Gaussian weight in s (section 4.2)


def _ori_pattern() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    i, j = np.mgrid[-_ORI_RADIUS : _ORI_RADIUS + 1, -_ORI_RADIUS : _ORI_RADIUS + 1]
    keep = i**2 + j**2 < _ORI_RADIUS**2  # 109 points strictly inside the circle
    u, v = j[keep].astype(np.float64), i[keep].astype(np.float64)
    w = np.exp(-(u**2 + v**2) / (2 * _ORI_SIGMA**2))
    return u, v, w


_ORI_U, _ORI_V, _ORI_W = _ori_pattern()
_DESC_T = np.arange(20, dtype=np.float64) - 9.5  # sample offsets along one side, in s
_DESC_W = np.exp(-(_DESC_T[:, None] ** 2 + _DESC_T[None, :] ** 2) / (2 * _DESC_SIGMA**2))


@numba.njit(cache=True, inline="always")
def _haar(ii, px, py, side):
    """Haar responses (dx, dy) of a ``side`` x ``side`` box (side even) centred at pixel
    (px, py), shifted inside the image where it would leave it."""
    height = ii.shape[0] - 1
    width = ii.shape[1] - 1
    side = min(side, height - height % 2, width - width % 2)
    h2 = side // 2
    x0 = min(max(px - h2, 0), width - side)
    y0 = min(max(py - h2, 0), height - side)
    dx = _box(ii, y0, x0 + h2, y0 + side, x0 + side) - _box(ii, y0, x0, y0 + side, x0 + h2)
    dy = _box(ii, y0 + h2, x0, y0 + side, x0 + side) - _box(ii, y0, x0, y0 + h2, x0 + side)
    return dx, dy


@numba.njit(cache=True)
def _orientations(ii, xs, ys, scales, pu, pv, pw, n_steps, window):
    n = xs.shape[0]
    m = pu.shape[0]
    out = np.zeros(n, dtype=np.float64)
    rx = np.empty(m)
    ry = np.empty(m)
    ang = np.empty(m)
    two_pi = 2.0 * math.pi
    for p in range(n):
        s = scales[p]
        side = max(2, 2 * int(math.floor(2.0 * s + 0.5)))  # Haar side 4 s, even
        for q in range(m):
            px = int(math.floor(xs[p] + pu[q] * s + 0.5))
            py = int(math.floor(ys[p] + pv[q] * s + 0.5))
            dx, dy = _haar(ii, px, py, side)
            rx[q] = pw[q] * dx
            ry[q] = pw[q] * dy
            ang[q] = math.atan2(dy, dx)
        best = -1.0
        bx = 0.0
        by = 0.0
        for w in range(n_steps):
            a0 = -math.pi + w * two_pi / n_steps
            sx = 0.0
            sy = 0.0
            for q in range(m):
                d = ang[q] - a0
                if d < 0.0:
                    d += two_pi
                if d < window:
                    sx += rx[q]
                    sy += ry[q]
            mag = sx * sx + sy * sy
            if mag > best:
                best = mag
                bx = sx
                by = sy
        out[p] = math.atan2(by, bx)
    return out


@numba.njit(cache=True)
def _descriptors(ii, xs, ys, scales, thetas, extended, offs, weights):
    n = xs.shape[0]
    per_cell = 8 if extended else 4
    dim = 16 * per_cell
    out = np.zeros((n, dim), dtype=np.float32)
    acc = np.zeros(dim)
    for p in range(n):
        s = scales[p]
        c = math.cos(thetas[p])
        sn = math.sin(thetas[p])
        side = max(2, 2 * int(math.floor(s + 0.5)))  # Haar side 2 s, even
        acc[:] = 0.0
        for b in range(20):
            v = offs[b]
            for a in range(20):
                u = offs[a]
                # (u, v) along the keypoint's axes (cos t, sin t) and (-sin t, cos t)
                gx = xs[p] + s * (c * u - sn * v)
                gy = ys[p] + s * (sn * u + c * v)
                dx, dy = _haar(ii, int(math.floor(gx + 0.5)), int(math.floor(gy + 0.5)), side)
                w = weights[b, a]
                tx = w * (c * dx + sn * dy)
                ty = w * (-sn * dx + c * dy)
                base = ((b // 5) * 4 + (a // 5)) * per_cell
                if extended:
                    if ty < 0.0:
                        acc[base] += tx
                        acc[base + 1] += abs(tx)
                    else:
                        acc[base + 2] += tx
                        acc[base + 3] += abs(tx)
                    if tx < 0.0:
                        acc[base + 4] += ty
                        acc[base + 5] += abs(ty)
                    else:
                        acc[base + 6] += ty
                        acc[base + 7] += abs(ty)
                else:
                    acc[base] += tx
                    acc[base + 1] += ty
                    acc[base + 2] += abs(tx)
                    acc[base + 3] += abs(ty)
        norm = 0.0
        for d in range(dim):
            norm += acc[d] * acc[d]
        if norm > 0.0:
            inv = 1.0 / math.sqrt(norm)
            for d in range(dim):
                out[p, d] = acc[d] * inv
    return out


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
) -> np.ndarray:
    """SURF descriptors (section 4.2) on an integral image, (N, 64) or (N, 128) float32.

    ``theta_image`` is the keypoint orientation in the image frame (clockwise on screen).
    """
    xy = np.ascontiguousarray(xy, dtype=np.float64).reshape(-1, 2)
    return _descriptors(
        ii,
        np.ascontiguousarray(xy[:, 0]),
        np.ascontiguousarray(xy[:, 1]),
        np.ascontiguousarray(scales, dtype=np.float64),
        np.ascontiguousarray(theta_image, dtype=np.float64),
        bool(extended),
        _DESC_T,
        _DESC_W,
    )
