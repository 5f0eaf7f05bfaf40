"""Ground truth for descriptor evaluation: keypoint regions as ellipses, projected through a
known homography, and their overlap error (Mikolajczyk et al., "A Comparison of Affine Region
Detectors", IJCV 65, 2005, section 3.1; used by Mikolajczyk and Schmid, PAMI 27(10), 2005).

A region is the ellipse ``{x : (x - c)^T M (x - c) <= 1}``. For similarity-covariant keypoints
``M = I / r^2`` with ``r = size_px / 2`` (OpenCV's size is a diameter); affine keypoints carry
``M`` in ``Keypoints.shape``. A region of image ``a`` is mapped into image ``b`` by the local
affine approximation of the homography at its centre: ``M_b = J^-T M J^-1`` with ``J`` the
Jacobian of ``H`` there (exact for affine ``H``, first order otherwise). The overlap error is

    eps = 1 - area(A_proj & B) / area(A_proj | B)

computed on a grid over the pair's bounding box. As in the Oxford benchmark (Mikolajczyk et
al. 2005, section 3.1), both ellipses are first rescaled about their centres by the factor
that gives the projected ``a`` region an equivalent radius ``det(M)^(-1/4)`` of
``normalise_px`` = 30 px, centres left where they are. This makes the test independent of
each detector's size convention (OpenCV's SIFT reports a blob diameter of about 2 sigma, our
SURF the 20 s side of its descriptor window, ORB its 31 px patch) so that methods are judged
alike: two equal regions then correspond when their centres are less than about 16 px apart
and their scales agree within a factor of about 1.4. ``normalise_px=None`` compares the
regions at their detected size times ``region_scale`` instead (stricter for small regions,
more lenient for large ones, and unfair between detectors).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vision.features import Keypoints

__all__ = [
    "Overlaps",
    "apply_homography",
    "ellipse_matrices",
    "ellipse_overlap_error",
    "overlap_errors",
    "project_regions",
]

_GRID = 32  # grid points per side of a pair's bounding box (area error about 1 %)


def ellipse_matrices(kp: Keypoints, region_scale: float = 1.0) -> np.ndarray:
    """Region matrices ``M`` (N, 2, 2) of keypoints: ``Keypoints.shape`` or ``I / (size/2)^2``,
    the ellipse enlarged ``region_scale`` times about its centre."""
    if kp.shape is not None:
        return np.array(kp.shape, dtype=np.float64) / region_scale**2
    r = np.maximum(region_scale * kp.size_px / 2.0, 1e-3)
    m = np.zeros((len(kp), 2, 2))
    m[:, 0, 0] = m[:, 1, 1] = 1.0 / r**2
    return m


def apply_homography(H: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Map points (N, 2) by the 3x3 homography ``H`` (pixels, OpenCV centre convention)."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    p = np.c_[xy, np.ones(len(xy))] @ np.asarray(H, dtype=np.float64).T
    return p[:, :2] / p[:, 2:3]


def project_regions(xy: np.ndarray, M: np.ndarray, H: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Project ellipses ``(xy, M)`` through ``H`` by its local affine approximation.

    Returns the centres (N, 2) and matrices ``J^-T M J^-1`` (N, 2, 2) in the target image,
    ``J`` the Jacobian of ``H`` at each centre.
    """
    H = np.asarray(H, dtype=np.float64)
    x, y = xy[:, 0], xy[:, 1]
    w = H[2, 0] * x + H[2, 1] * y + H[2, 2]
    u = (H[0, 0] * x + H[0, 1] * y + H[0, 2]) / w
    v = (H[1, 0] * x + H[1, 1] * y + H[1, 2]) / w
    J = np.empty((len(xy), 2, 2))
    J[:, 0, 0] = (H[0, 0] - u * H[2, 0]) / w
    J[:, 0, 1] = (H[0, 1] - u * H[2, 1]) / w
    J[:, 1, 0] = (H[1, 0] - v * H[2, 0]) / w
    J[:, 1, 1] = (H[1, 1] - v * H[2, 1]) / w
    Ji = np.linalg.inv(J)
    Mp = np.transpose(Ji, (0, 2, 1)) @ M @ Ji
    return np.c_[u, v], 0.5 * (Mp + np.transpose(Mp, (0, 2, 1)))


def _half_extent(M: np.ndarray) -> np.ndarray:
    """Half-widths (N, 2) of the axis-aligned boxes of ellipses ``M``."""
    C = np.linalg.inv(M)
    return np.sqrt(np.stack([C[:, 0, 0], C[:, 1, 1]], axis=1))


def ellipse_overlap_error(
    c1: np.ndarray, M1: np.ndarray, c2: np.ndarray, M2: np.ndarray, *, grid: int = _GRID
) -> np.ndarray:
    """Overlap error ``1 - |E1 & E2| / |E1 | E2|`` of ellipse pairs, on a grid per pair.

    Parameters
    ----------
    c1, c2 : ndarray of shape (K, 2)
        Centres.
    M1, M2 : ndarray of shape (K, 2, 2)
        Symmetric positive definite matrices, ellipse ``(x - c)^T M (x - c) <= 1``.
    grid : int
        Sample points per side of each pair's bounding box (cell centres).

    Returns
    -------
    ndarray of shape (K,)
        Overlap errors in [0, 1].
    """
    c1, c2 = np.atleast_2d(c1), np.atleast_2d(c2)
    M1, M2 = np.reshape(M1, (-1, 2, 2)), np.reshape(M2, (-1, 2, 2))
    out = np.empty(len(c1))
    t = (np.arange(grid) + 0.5) / grid
    for s in range(0, len(c1), 2048):
        sl = slice(s, s + 2048)
        e1, e2 = _half_extent(M1[sl]), _half_extent(M2[sl])
        lo = np.minimum(c1[sl] - e1, c2[sl] - e2)
        hi = np.maximum(c1[sl] + e1, c2[sl] + e2)
        gx = lo[:, 0:1, None] + (hi - lo)[:, 0:1, None] * t[None, None, :]  # (k, 1, g)
        gy = lo[:, 1:2, None] + (hi - lo)[:, 1:2, None] * t[None, :, None]  # (k, g, 1)
        inside = []
        for c, M in ((c1[sl], M1[sl]), (c2[sl], M2[sl])):
            dx = gx - c[:, 0, None, None]
            dy = gy - c[:, 1, None, None]
            q = (
                M[:, 0, 0, None, None] * dx * dx
                + 2.0 * M[:, 0, 1, None, None] * dx * dy
                + M[:, 1, 1, None, None] * dy * dy
            )
            inside.append(q <= 1.0)
        inter = np.count_nonzero(inside[0] & inside[1], axis=(1, 2))
        union = np.count_nonzero(inside[0] | inside[1], axis=(1, 2))
        out[sl] = 1.0 - inter / np.maximum(union, 1)
    return out


@dataclass(frozen=True, eq=False)
class Overlaps:
    """Region pairs of images ``a`` and ``b`` whose overlap error is below ``max_error``.

    Attributes
    ----------
    index_a, index_b : ndarray of shape (K,), int64
        Keypoint indices of each overlapping pair.
    error : ndarray of shape (K,)
        Their overlap errors.
    max_error : float
        The threshold (0.5 in the chapter and in Mikolajczyk and Schmid 2005).
    """

    index_a: np.ndarray
    index_b: np.ndarray
    error: np.ndarray
    max_error: float


def overlap_errors(
    kp_a: Keypoints,
    kp_b: Keypoints,
    H: np.ndarray,
    *,
    max_error: float = 0.5,
    region_scale: float = 1.0,
    normalise_px: float | None = 30.0,
) -> Overlaps:
    """All region pairs with overlap error below ``max_error`` under the homography ``H``.

    Parameters
    ----------
    kp_a, kp_b : Keypoints
        Regions of images ``a`` and ``b``.
    H : ndarray of shape (3, 3)
        Ground truth mapping pixels of ``a`` to ``b``.
    max_error : float
        Overlap error threshold, in (0, 1).
    region_scale : float
        Regions are the keypoint ellipses enlarged this many times (no effect when
        normalising, apart from the candidate search).
    normalise_px : float or None
        Equivalent radius the projected ``a`` region is scaled to (module docstring); ``None``
        compares the regions at their detected size.
    """
    if not 0.0 < max_error < 1.0:
        raise ValueError(f"max_error must be in (0, 1), got {max_error!r}")
    H = np.asarray(H, dtype=np.float64)
    if H.shape != (3, 3) or not np.all(np.isfinite(H)):
        raise ValueError(f"H must be a finite 3x3 matrix, got shape {H.shape}")
    empty = np.zeros(0, dtype=np.int64)
    if len(kp_a) == 0 or len(kp_b) == 0:
        return Overlaps(empty, empty, np.zeros(0), max_error)
    if not region_scale > 0:
        raise ValueError(f"region_scale must be positive, got {region_scale!r}")
    ca, Ma = project_regions(kp_a.xy, ellipse_matrices(kp_a, region_scale), H)
    cb, Mb = kp_b.xy, ellipse_matrices(kp_b, region_scale)
    # Equivalent radius r = det(M)^(-1/4); scale factor f per a-region (applied to both).
    ra = np.linalg.det(Ma) ** -0.25
    rb = np.linalg.det(Mb) ** -0.25
    # Candidate pairs: IoU <= (smaller area / larger area), and the ellipses must touch.
    big_a = 1.0 / np.sqrt(np.linalg.eigvalsh(Ma)[:, 0])
    big_b = 1.0 / np.sqrt(np.linalg.eigvalsh(Mb)[:, 0])
    area_lim = 1.0 - max_error
    ia_all, ib_all = [], []
    for s in range(0, len(ca), 512):
        sl = slice(s, s + 512)
        d = np.linalg.norm(ca[sl, None, :] - cb[None, :, :], axis=2)
        f = 1.0 if normalise_px is None else normalise_px / ra[sl, None]
        reach = f * (big_a[sl, None] + big_b[None, :])
        rr = (ra[sl, None] / rb[None, :]) ** 2
        ok = (d < reach) & (np.minimum(rr, 1.0 / rr) > area_lim * 0.95)
        i, j = np.nonzero(ok)
        ia_all.append(i + s)
        ib_all.append(j)
    ia = np.concatenate(ia_all).astype(np.int64)
    ib = np.concatenate(ib_all).astype(np.int64)
    if len(ia) == 0:
        return Overlaps(empty, empty, np.zeros(0), max_error)
    f2 = 1.0 if normalise_px is None else (normalise_px / ra[ia])[:, None, None] ** 2
    err = ellipse_overlap_error(ca[ia], Ma[ia] / f2, cb[ib], Mb[ib] / f2)
    keep = err < max_error
    return Overlaps(ia[keep], ib[keep], err[keep], max_error)
