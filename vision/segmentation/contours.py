"""Closed contours: initialisations, arc-length resampling, masks and scores.

Convention for the whole package: a contour is an ``(N, 2)`` float array of ``(x, y)``
pixel positions, ``x`` = column and ``y`` = row, pixel centres at integers, the first
point not repeated at the end.  This is OpenCV's and :class:`~vision.camera.PinholeCamera`'s
``(u, v)`` order; scikit-image's ``active_contour`` uses ``(row, col)`` instead, so its
contours are ``contour[:, ::-1]`` of ours.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from vision.errors import ImageError
from vision.segmentation.validation import check_image, check_int, check_positive

__all__ = [
    "blob_contour",
    "box_contour",
    "circle_contour",
    "contour_from_mask",
    "ellipse_contour",
    "iou",
    "mask_from_contour",
    "polygon_area",
    "remove_loops",
    "resample_closed",
]


def circle_contour(
    center_xy: tuple[float, float], radius_px: float, n_points: int = 100
) -> NDArray[np.float64]:
    """``n_points`` points evenly spaced on a circle, clockwise on screen (y down)."""
    return ellipse_contour(center_xy, (radius_px, radius_px), n_points=n_points)


def ellipse_contour(
    center_xy: tuple[float, float],
    axes_px: tuple[float, float],
    *,
    angle_deg: float = 0.0,
    n_points: int = 100,
) -> NDArray[np.float64]:
    """Points on an ellipse with semi-axes ``axes_px`` rotated by ``angle_deg`` (x towards y)."""
    a = check_positive(axes_px[0], "axes_px[0]")
    b = check_positive(axes_px[1], "axes_px[1]")
    n = check_int(n_points, "n_points", minimum=5)
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    c, s = np.cos(np.radians(angle_deg)), np.sin(np.radians(angle_deg))
    ex, ey = a * np.cos(t), b * np.sin(t)
    return np.stack([center_xy[0] + c * ex - s * ey, center_xy[1] + s * ex + c * ey], axis=1)


def box_contour(
    x0: float, y0: float, x1: float, y1: float, n_points: int = 100
) -> NDArray[np.float64]:
    """Points evenly spaced (by arc length) along the rectangle with corners (x0, y0), (x1, y1)."""
    if not (x1 > x0 and y1 > y0):
        raise ValueError(f"box needs x1 > x0 and y1 > y0, got ({x0}, {y0}, {x1}, {y1})")
    corners = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=np.float64)
    return resample_closed(corners, n_points)


def polygon_area(contour: ArrayLike) -> float:
    """Signed area (shoelace); positive when the points turn clockwise on screen (y down)."""
    c = np.asarray(contour, dtype=np.float64)
    x, y = c[:, 0], c[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def resample_closed(contour: ArrayLike, n_points: int) -> NDArray[np.float64]:
    """Resample a closed polyline to ``n_points`` points equally spaced in arc length.

    Linear interpolation along the polygon; the first point is kept.  Repeated points
    (zero-length edges) are tolerated.
    """
    c = np.asarray(contour, dtype=np.float64)
    n = check_int(n_points, "n_points", minimum=3)
    closed = np.vstack([c, c[:1]])
    seg = np.hypot(*np.diff(closed, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    if s[-1] <= 0.0:
        raise ValueError(f"contour has zero length ({c.shape[0]} coincident points)")
    t = np.linspace(0.0, s[-1], n, endpoint=False)
    return np.stack([np.interp(t, s, closed[:, 0]), np.interp(t, s, closed[:, 1])], axis=1)


def mask_from_contour(contour: ArrayLike, shape: tuple[int, ...]) -> NDArray[np.bool_]:
    """Pixels whose centre lies inside a closed contour, as a boolean ``(H, W)`` mask.

    Scanline even-odd fill at the pixel centres: every edge contributes one crossing per
    pixel row ``y`` in its half-open span ``[min(y0, y1), max(y0, y1))``; per row the sorted
    crossings pair up as (enter, leave) and the pixels with centre ``x`` in ``[enter, leave)``
    are inside.  Unlike ``cv2.fillPoly`` (which also sets the pixels the outline touches,
    about half a pixel of bias outwards), the mask's area matches the polygon's area.
    """
    h, w = shape[:2]
    c = np.asarray(contour, dtype=np.float64)
    mask = np.zeros((h, w), dtype=bool)
    if c.shape[0] < 3:
        return mask
    p, q = c, np.roll(c, -1, axis=0)
    lo = np.ceil(np.minimum(p[:, 1], q[:, 1])).astype(np.intp)
    hi = np.ceil(np.maximum(p[:, 1], q[:, 1])).astype(np.intp)
    k = np.maximum(hi - lo, 0)
    total = int(k.sum())
    if total == 0:
        return mask
    edge = np.repeat(np.arange(c.shape[0]), k)
    row = lo[edge] + (np.arange(total) - np.repeat(np.cumsum(k) - k, k))
    pe, qe = p[edge], q[edge]
    x = pe[:, 0] + (row - pe[:, 1]) / (qe[:, 1] - pe[:, 1]) * (qe[:, 0] - pe[:, 0])
    keep = (row >= 0) & (row < h)  # whole rows go, so every kept row keeps an even count
    row, x = row[keep], x[keep]
    if row.size == 0:
        return mask
    order = np.lexsort((x, row))
    row, x = row[order], x[order]
    r, a = row[0::2], np.clip(np.ceil(x[0::2]), 0, w).astype(np.intp)
    b = np.clip(np.ceil(x[1::2]), 0, w).astype(np.intp)
    # Fill only the bounding box of the spans: a difference array per row, summed along x.
    r0, r1 = int(r.min()), int(r.max()) + 1
    c0, c1 = int(a.min()), int(b.max())
    if c1 <= c0:
        return mask
    width = c1 - c0 + 1
    size = (r1 - r0) * width
    diff = np.bincount((r - r0) * width + (a - c0), minlength=size) - np.bincount(
        (r - r0) * width + (b - c0), minlength=size
    )
    mask[r0:r1, c0:c1] = np.cumsum(diff.reshape(r1 - r0, width), axis=1)[:, : c1 - c0] > 0
    return mask


def contour_from_mask(mask: ArrayLike, n_points: int | None = None) -> NDArray[np.float64]:
    """Outer boundary of the largest connected region of ``mask`` as an ``(x, y)`` contour.

    The boundary runs through the centres of the region's edge pixels (``cv2.findContours``);
    with ``n_points`` it is resampled by arc length.  An empty mask gives an empty (0, 2) array.
    """
    m = np.asarray(mask).astype(np.uint8)
    found, _ = cv2.findContours(m, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    if not found:
        return np.zeros((0, 2))
    best = max(found, key=cv2.contourArea)[:, 0, :].astype(np.float64)
    if n_points is not None and best.shape[0] >= 2:
        return resample_closed(best, n_points)
    return best


def iou(mask_a: ArrayLike, mask_b: ArrayLike) -> float:
    """Intersection over union of two boolean masks of the same shape (1.0 when both empty)."""
    a, b = np.asarray(mask_a, bool), np.asarray(mask_b, bool)
    if a.shape != b.shape:
        raise ValueError(f"masks differ in shape: {a.shape} vs {b.shape}")
    union = np.count_nonzero(a | b)
    return 1.0 if union == 0 else np.count_nonzero(a & b) / union


def blob_contour(
    image: NDArray[np.generic],
    *,
    n_points: int = 100,
    polarity: str = "auto",
    sigma_px: float = 1.0,
) -> NDArray[np.float64]:
    """Initial contour: the outline of the largest blob after Otsu thresholding (Otsu 1979).

    Parameters
    ----------
    image : ndarray of shape (H, W) or (H, W, 3)
        Grey or RGB image (colour is reduced to luminance).
    n_points : int
        Points of the returned contour (resampled by arc length).
    polarity : {"auto", "bright", "dark"}
        Whether the object is brighter or darker than its surroundings; ``"auto"`` takes the
        class that touches the image border less.
    sigma_px : float
        Gaussian smoothing before thresholding.

    Raises
    ------
    ImageError
        When the image is constant (no threshold separates anything).
    """
    img = check_image(image)
    if polarity not in ("auto", "bright", "dark"):
        raise ValueError(f"polarity must be 'auto', 'bright' or 'dark', got {polarity!r}")
    grey = img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
    grey = cv2.GaussianBlur(grey, (0, 0), check_positive(sigma_px, "sigma_px"))
    g8 = np.round(grey * 255.0).astype(np.uint8)
    if int(g8.max()) == int(g8.min()):
        raise ImageError("image is constant: Otsu's threshold cannot find a blob")
    _, bright = cv2.threshold(g8, 0, 1, cv2.THRESH_BINARY | cv2.THRESH_OTSU)
    if polarity == "auto":
        border = np.concatenate([bright[0], bright[-1], bright[:, 0], bright[:, -1]])
        polarity = "bright" if border.mean() < 0.5 else "dark"
    fg = bright if polarity == "bright" else 1 - bright
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))
    fg = cv2.morphologyEx(fg.astype(np.uint8), cv2.MORPH_OPEN, kernel)
    c = contour_from_mask(fg, n_points)
    if c.shape[0] == 0:
        raise ImageError("Otsu thresholding left no blob to outline")
    return c


def remove_loops(contour: ArrayLike, *, max_loops: int = 50) -> NDArray[np.float64]:
    """Cut self-intersection loops out of a closed contour, keeping the larger part each time.

    Where edges ``i`` and ``j`` cross, the polygon splits into the loop ``i+1 .. j`` and the
    rest; the part with the smaller absolute area is dropped and the crossing point joins the
    two ends.  A snake pulled by a distracting edge can fold over itself this way; the loop
    carries no object area and would otherwise grow at each resampling.  (Compiled: the
    snake calls the same code at every resampling.)
    """
    c = np.ascontiguousarray(contour, dtype=np.float64)
    if c.ndim != 2 or c.shape[1] != 2:
        raise ValueError(f"contour must have shape (N, 2), got {c.shape}")
    from vision.segmentation import _kernels  # Numba: load only when needed

    return _kernels.remove_loops(c, check_int(max_loops, "max_loops", minimum=1))
