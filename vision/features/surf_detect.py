"""SURF detector: box-filter Hessian over octaves, 3x3x3 non-maximum suppression, quadratic fit.

Bay, Ess, Tuytelaars and Van Gool, "Speeded-Up Robust Features (SURF)", CVIU 110(3), 2008,
section 3 (the "Fast-Hessian" detector). The second derivatives of a Gaussian are replaced by
box filters of size ``L x L`` (``L = 9, 15, 21, 27`` in the first octave), evaluated in constant
time on the integral image, and the scale-normalised determinant of the Hessian is
approximated by (paper eq. 4)

    det(H_approx) = Dxx Dyy - (0.9 Dxy)^2,

each response divided by the filter area ``L^2``. Octave ``o`` (0-based) holds the four filter
sizes ``L = 3 (2^(o+1) (k+1) + 1)``, ``k = 0..3`` (9, 15, 21, 27; 15, 27, 39, 51; 27, 51, 75,
99; ...) sampled every ``2^o`` pixels. A filter of size ``L`` corresponds to a Gaussian of
``sigma = s = 1.2 L / 9``.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["detect_hessian", "filter_sizes", "integral_image"]

#: Relative weight of Dxy in the determinant (paper eq. 4, w = 0.912 rounded).
DXY_WEIGHT = 0.9
#: Gaussian scale of the 9x9 filters (paper section 3.2).
BASE_SCALE = 1.2
LAYERS_PER_OCTAVE = 4


def integral_image(image: np.ndarray) -> np.ndarray:
    """Summed-area table ``ii`` of shape (H + 1, W + 1), float64: ``ii[r, c] = sum image[:r, :c]``
    (paper eq. 1). An (H, W, C) image gives one table per channel, (H + 1, W + 1, C)."""
    img = np.asarray(image, dtype=np.float64)
    ii = np.zeros((img.shape[0] + 1, img.shape[1] + 1, *img.shape[2:]), dtype=np.float64)
    np.cumsum(np.cumsum(img, axis=0), axis=1, out=ii[1:, 1:])
    return ii


def filter_sizes(octave: int) -> tuple[int, ...]:
    """Box-filter sizes ``L`` of one octave (0-based): 9, 15, 21, 27 for octave 0."""
    return tuple(3 * ((2 ** (octave + 1)) * (k + 1) + 1) for k in range(LAYERS_PER_OCTAVE))


@numba.njit(cache=True, inline="always")
def _box(ii, r0, c0, r1, c1):
    """Sum over rows [r0, r1) and columns [c0, c1) from the integral image."""
    return ii[r1, c1] - ii[r0, c1] - ii[r1, c0] + ii[r0, c0]


@numba.njit(cache=True)
def _hessian_layer(ii, size, step, nrows, ncols):
    """det(H_approx) of one filter size on the grid ``(i * step, j * step)``; 0 where the
    filter does not fit in the image."""
    height = ii.shape[0] - 1
    width = ii.shape[1] - 1
    lobe = size // 3  # lobe length l = L / 3
    half = (size - 1) // 2  # the filter spans centre +- half
    mid = (lobe - 1) // 2  # the middle lobe spans centre +- mid
    inv_area = 1.0 / (size * size)
    w2 = DXY_WEIGHT * DXY_WEIGHT
    out = np.zeros((nrows, ncols), dtype=np.float32)
    for i in range(nrows):
        y = i * step
        if y - half < 0 or y + half >= height:
            continue
        for j in range(ncols):
            x = j * step
            if x - half < 0 or x + half >= width:
                continue
            # Dyy: lobes +1, -2, +1 stacked vertically, each l tall and 2l - 1 wide, written as
            # the whole L x (2l - 1) box minus three times the middle lobe.
            dyy = _box(ii, y - half, x - lobe + 1, y + half + 1, x + lobe) - 3.0 * _box(
                ii, y - mid, x - lobe + 1, y + mid + 1, x + lobe
            )
            dxx = _box(ii, y - lobe + 1, x - half, y + lobe, x + half + 1) - 3.0 * _box(
                ii, y - lobe + 1, x - mid, y + lobe, x + mid + 1
            )
            # Dxy: four l x l lobes around the centre, one pixel apart; + on the diagonal
            # (top-left, bottom-right), - off it, as for d2(xy)/dx dy with y pointing down.
            dxy = (
                _box(ii, y - lobe, x - lobe, y, x)
                + _box(ii, y + 1, x + 1, y + lobe + 1, x + lobe + 1)
                - _box(ii, y - lobe, x + 1, y, x + lobe + 1)
                - _box(ii, y + 1, x - lobe, y + lobe + 1, x)
            )
            dxx *= inv_area
            dyy *= inv_area
            dxy *= inv_area
            out[i, j] = dxx * dyy - w2 * dxy * dxy
    return out


@numba.njit(cache=True)
def _extrema(dets, sizes, step, height, width, threshold):
    """Strict 3x3x3 maxima above ``threshold`` in the middle layers of one octave, refined by
    a 3D quadratic fit (Brown and Lowe 2002, as in the paper section 3.3).

    Returns rows ``(x, y, L, response)``.
    """
    n_layers, nrows, ncols = dets.shape
    found = []
    for k in range(1, n_layers - 1):
        # the neighbourhood must lie where the largest filter of the triple fits
        half = (sizes[k + 1] - 1) // 2
        i_lo = (half + step - 1) // step + 1
        i_hi = (height - 1 - half) // step - 1
        j_lo = i_lo
        j_hi = (width - 1 - half) // step - 1
        dl = sizes[k + 1] - sizes[k]
        for i in range(i_lo, min(i_hi, nrows - 2) + 1):
            for j in range(j_lo, min(j_hi, ncols - 2) + 1):
                v = dets[k, i, j]
                if v <= threshold:
                    continue
                is_max = True
                for dk in range(-1, 2):
                    for di in range(-1, 2):
                        for dj in range(-1, 2):
                            if dk == 0 and di == 0 and dj == 0:
                                continue
                            if dets[k + dk, i + di, j + dj] >= v:
                                is_max = False
                                break
                        if not is_max:
                            break
                    if not is_max:
                        break
                if not is_max:
                    continue
                # gradient and Hessian of the response in (x, y, layer) grid units
                gx = 0.5 * (dets[k, i, j + 1] - dets[k, i, j - 1])
                gy = 0.5 * (dets[k, i + 1, j] - dets[k, i - 1, j])
                gs = 0.5 * (dets[k + 1, i, j] - dets[k - 1, i, j])
                hxx = dets[k, i, j + 1] + dets[k, i, j - 1] - 2.0 * v
                hyy = dets[k, i + 1, j] + dets[k, i - 1, j] - 2.0 * v
                hss = dets[k + 1, i, j] + dets[k - 1, i, j] - 2.0 * v
                hxy = 0.25 * (
                    dets[k, i + 1, j + 1]
                    - dets[k, i + 1, j - 1]
                    - dets[k, i - 1, j + 1]
                    + dets[k, i - 1, j - 1]
                )
                hxs = 0.25 * (
                    dets[k + 1, i, j + 1]
                    - dets[k + 1, i, j - 1]
                    - dets[k - 1, i, j + 1]
                    + dets[k - 1, i, j - 1]
                )
                hys = 0.25 * (
                    dets[k + 1, i + 1, j]
                    - dets[k + 1, i - 1, j]
                    - dets[k - 1, i + 1, j]
                    + dets[k - 1, i - 1, j]
                )
                # offset = -H^-1 g by Cramer's rule
                det = (
                    hxx * (hyy * hss - hys * hys)
                    - hxy * (hxy * hss - hys * hxs)
                    + hxs * (hxy * hys - hyy * hxs)
                )
                if det == 0.0:
                    continue
                bx, by, bs = -gx, -gy, -gs
                ox = (
                    bx * (hyy * hss - hys * hys)
                    - hxy * (by * hss - hys * bs)
                    + hxs * (by * hys - hyy * bs)
                ) / det
                oy = (
                    hxx * (by * hss - hys * bs)
                    - bx * (hxy * hss - hys * hxs)
                    + hxs * (hxy * bs - by * hxs)
                ) / det
                os_ = (
                    hxx * (hyy * bs - by * hys)
                    - hxy * (hxy * bs - by * hxs)
                    + bx * (hxy * hys - hyy * hxs)
                ) / det
                if abs(ox) > 1.0 or abs(oy) > 1.0 or abs(os_) > 1.0:
                    continue
                response = v + 0.5 * (gx * ox + gy * oy + gs * os_)
                found.append(
                    (
                        (j + ox) * step,
                        (i + oy) * step,
                        sizes[k] + os_ * dl,
                        response,
                    )
                )
    out = np.empty((len(found), 4), dtype=np.float64)
    for n in range(len(found)):
        out[n, 0] = found[n][0]
        out[n, 1] = found[n][1]
        out[n, 2] = found[n][2]
        out[n, 3] = found[n][3]
    return out


def detect_hessian(
    ii: np.ndarray, n_octaves: int, threshold: float
) -> tuple[np.ndarray, np.ndarray]:
    """Fast-Hessian interest points of an integral image.

    Parameters
    ----------
    ii : ndarray of shape (H + 1, W + 1), float64
        Integral image (:func:`integral_image`) of the grey image.
    n_octaves : int
        Number of octaves; octaves whose largest filter does not fit are skipped.
    threshold : float
        Minimum ``det(H_approx)`` of a maximum (responses are divided by ``L^2``, so the unit is
        image value squared per pixel^4).

    Returns
    -------
    points : ndarray of shape (N, 4), float64
        ``(x, y, L, response)`` with ``L`` the interpolated filter size.
    octave : ndarray of shape (N,), int32
    """
    height, width = ii.shape[0] - 1, ii.shape[1] - 1
    rows, octaves = [], []
    for o in range(n_octaves):
        sizes = np.array(filter_sizes(o), dtype=np.int64)
        step = 2**o
        if sizes[-1] + 2 * step > min(height, width):
            break
        nrows = (height - 1) // step + 1
        ncols = (width - 1) // step + 1
        dets = np.stack([_hessian_layer(ii, int(L), step, nrows, ncols) for L in sizes])
        pts = _extrema(dets, sizes, step, height, width, float(threshold))
        rows.append(pts)
        octaves.append(np.full(len(pts), o, dtype=np.int32))
    if not rows:
        return np.zeros((0, 4)), np.zeros(0, dtype=np.int32)
    return np.concatenate(rows), np.concatenate(octaves)
