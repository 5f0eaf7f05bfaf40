"""The object's region in a view: the chapter's active contour (section 3.2, eqs. 6-11)
initialised from the difference with the empty-belt background.

1. Foreground: the per-pixel largest channel difference between the (slightly blurred)
   image and the background of the same viewpoint, thresholded at ``min_diff`` grey levels
   (a fixed level: a dark part on the dark belt under dimmed light can fall below it),
   opened and closed, and the largest connected blob kept with its holes filled.  This is
   where the object is, roughly: shadows and the belt seen through holes move its edge by
   a few pixels.
2. Initial contour: the blob's convex hull pushed out by ``margin_px`` along its normals
   (the loose contour around the object that the chapter's operator would draw).
3. The snake (:func:`vision.segmentation.active_contour`, eq. 8 with the edge energy of
   eq. 11) shrinks from there under a small balloon pressure (Cohen 1991) that fades on
   edges, and stops on the object's outline.  Its inside is the object's mask.
4. The snake's tension (eq. 8's first-order term) cuts across a narrow neck as it shrinks:
   the pipe flange's side nozzle and the gear housing's shaft were left out (the snake's
   region missed 7.7 % of the flange's true silhouette, and without the nozzle's features
   the bolt circle registered a sixth of a turn off).  The parts of the step-1 blob
   outside the snake's region that are not the belt in shadow (:func:`cut_off_parts`)
   are added back, joined by their necks.  Overlap with the true silhouette in the
   simulator's top views (``python -m benchmarks.segment_parts``, 4 yaws per part, snake
   alone -> with the cut-off parts): pipe flange 0.921 -> 0.981, gear housing 0.912 ->
   0.969, bracket upright 0.877 -> 0.973, bracket flat 0.895 -> 0.960; the wheels and the
   other parts unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from vision.errors import VisionCellError
from vision.segmentation import active_contour, iou, mask_from_contour, resample_closed

__all__ = [
    "ObjectRegion",
    "SegmentationFailed",
    "cut_off_parts",
    "foreground_mask",
    "segment_object",
]


class SegmentationFailed(VisionCellError):
    """No object could be separated from the background."""

    code = "segmentation_failed"


@dataclass(frozen=True, eq=False)
class ObjectRegion:
    """The object's region in one image.

    Attributes
    ----------
    mask : ndarray of shape (H, W), bool
        Inside the final contour.
    contour : ndarray of shape (N, 2), float64
        Final closed contour, ``(x, y)`` pixels.
    initial_mask : ndarray of shape (H, W), bool
        The background-difference blob (step 1).
    init : ndarray of shape (N, 2), float64
        Initial contour of the snake (step 2).
    iterations : int
        Snake iterations.
    converged : bool
        Whether the snake met its movement test.
    method : str
        ``"active contour"``, or ``"background difference"`` when the snake left the
        object (its region disagreed with the blob) and the blob was kept instead.
    note : str
        Why the fallback was taken (empty otherwise).
    """

    mask: NDArray[np.bool_]
    contour: NDArray[np.float64]
    initial_mask: NDArray[np.bool_]
    init: NDArray[np.float64]
    iterations: int
    converged: bool
    method: str = "active contour"
    note: str = ""


def _check_pair(image: NDArray[np.uint8], background: NDArray[np.uint8]) -> None:
    for name, a in (("image", image), ("background", background)):
        if not isinstance(a, np.ndarray) or a.dtype != np.uint8 or a.ndim != 3 or a.shape[2] != 3:
            raise ValueError(f"{name} must be RGB uint8 (H, W, 3), got {getattr(a, 'shape', a)}")
    if image.shape != background.shape:
        raise ValueError(
            f"image {image.shape} and background {background.shape} must have the same shape"
        )


def foreground_mask(
    image: NDArray[np.uint8],
    background: NDArray[np.uint8],
    *,
    min_diff: int = 12,
    min_area_frac: float = 0.002,
    near_px: ArrayLike | None = None,
) -> NDArray[np.bool_]:
    """The largest blob that differs from ``background`` (step 1), holes filled; with
    ``near_px``, the blob nearest that pixel instead, of those at least a tenth of the
    largest (the station's pixel: a neighbour on the belt, partly in view, may be larger
    than the part at the station; a speck of noise is not a part).

    Parameters
    ----------
    image, background : ndarray of shape (H, W, 3), uint8
        The view with the object, and the same view with the belt empty.
    min_diff : int
        Smallest channel difference (grey levels) counted as foreground.
    min_area_frac : float
        Smallest blob, as a fraction of the image area.
    near_px : array_like of shape (2,), optional
        ``(u, v)`` pixel: of the blobs of at least ``min_area_frac`` and a tenth of the
        largest blob, the one with a pixel nearest it (ties: the larger).

    Raises
    ------
    SegmentationFailed
        Nothing differs enough from the background.
    """
    _check_pair(image, background)
    near = None
    if near_px is not None:
        near = np.asarray(near_px, dtype=np.float64).reshape(-1)
        if near.shape != (2,) or not np.isfinite(near).all():
            raise ValueError(f"near_px must be a finite (u, v) pixel, got {near_px!r}")
    a = cv2.GaussianBlur(image, (5, 5), 1.2).astype(np.int16)
    b = cv2.GaussianBlur(background, (5, 5), 1.2).astype(np.int16)
    diff = np.abs(a - b).max(axis=2).astype(np.uint8)
    fg = (diff > min_diff).astype(np.uint8)
    fg = cv2.morphologyEx(fg, cv2.MORPH_OPEN, np.ones((5, 5), np.uint8))
    fg = cv2.morphologyEx(fg, cv2.MORPH_CLOSE, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (9, 9)))
    n, labels, stats, _ = cv2.connectedComponentsWithStats(fg, connectivity=8)
    if n <= 1:
        raise SegmentationFailed("nothing in the image differs from the empty-belt background")
    k = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    min_area = min_area_frac * image.shape[0] * image.shape[1]
    if near is not None:
        least = max(min_area, NEAR_MIN_SHARE * float(stats[k, cv2.CC_STAT_AREA]))
        k = _nearest_blob(labels, stats, near, least, default=k)
    area = int(stats[k, cv2.CC_STAT_AREA])
    if area < min_area:
        raise SegmentationFailed(
            f"the largest change from the background covers {area} px, under "
            f"{min_area_frac:.1%} of the image: is the object at the station?"
        )
    return _fill(labels == k)


def _initial_contour(
    blob: NDArray[np.bool_], margin_px: float, n_points: int
) -> NDArray[np.float64]:
    contours, _ = cv2.findContours(blob.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    hull = cv2.convexHull(max(contours, key=cv2.contourArea)).reshape(-1, 2).astype(np.float64)
    pts = resample_closed(hull, n_points)
    # Outward normals of a counter-clockwise (on screen: y down) polygon, by central differences.
    tangent = np.roll(pts, -1, axis=0) - np.roll(pts, 1, axis=0)
    normal = np.stack([tangent[:, 1], -tangent[:, 0]], axis=1)
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-9)
    centre = pts.mean(axis=0)
    if np.mean(np.sum((pts - centre) * normal, axis=1)) < 0:  # make them point outward
        normal = -normal
    h, w = blob.shape
    out = pts + margin_px * normal
    out[:, 0] = np.clip(out[:, 0], 1.0, w - 2.0)
    out[:, 1] = np.clip(out[:, 1], 1.0, h - 2.0)
    return out


def segment_object(
    image: NDArray[np.uint8],
    background: NDArray[np.uint8],
    *,
    margin_px: float = 10.0,
    balloon: float = -0.6,
    n_points: int = 200,
    max_num_iter: int = 600,
    min_agreement: float = 0.6,
    recover_cut: bool = True,
    near_px: ArrayLike | None = None,
) -> ObjectRegion:
    """Segment the object in ``image`` against ``background`` (module docstring).

    Parameters
    ----------
    image, background : ndarray of shape (H, W, 3), uint8
        RGB view with the object, and the same view with the belt empty.
    margin_px : float
        How far outside the foreground's convex hull the snake starts, pixels.
    balloon : float
        Pressure along the normal (negative: shrink), see ``active_contour``.
    n_points, max_num_iter : int
        Snake size and iteration cap.
    min_agreement : float
        Smallest IoU between the snake's region and the foreground blob; below it the
        snake is taken to have left the object (it may have collapsed through a weak edge,
        or the object touches the image border) and the blob is the region instead, with
        ``method="background difference"`` and the reason in ``note``.
    recover_cut : bool
        Add back the parts of the foreground the snake cut off (:func:`cut_off_parts`):
        ``method="active contour + cut-off parts"``, the pixels added in ``note``.
    near_px : array_like of shape (2,), optional
        Segment the blob nearest this pixel (:func:`foreground_mask`), not the largest.

    Raises
    ------
    SegmentationFailed
        Nothing differs enough from the background.
    """
    if not 0.0 <= margin_px <= 100.0:
        raise ValueError(f"margin_px must be in [0, 100], got {margin_px!r}")
    blob = foreground_mask(image, background, near_px=near_px)
    init = _initial_contour(blob, margin_px, n_points)
    snake = active_contour(image, init, balloon=balloon, max_num_iter=max_num_iter)
    mask = mask_from_contour(snake.contour, blob.shape)
    agreement = iou(mask, blob)
    if agreement < min_agreement:
        contours, _ = cv2.findContours(
            blob.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE
        )
        outline = max(contours, key=cv2.contourArea).reshape(-1, 2).astype(np.float64)
        return ObjectRegion(
            blob,
            outline,
            blob,
            init,
            snake.iterations,
            snake.converged,
            method="background difference",
            note=f"the active contour left the object (IoU {agreement:.2f} with the "
            f"background difference, under {min_agreement})",
        )
    if not recover_cut:
        return ObjectRegion(mask, snake.contour, blob, init, snake.iterations, snake.converged)
    cut = cut_off_parts(image, background, blob, mask)
    if not cut.any():
        return ObjectRegion(mask, snake.contour, blob, init, snake.iterations, snake.converged)
    # the pieces and the necks joining them: the union closed near the pieces only
    union = (mask | cut).astype(np.uint8)
    ell = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (9, 9))
    bridged = cv2.morphologyEx(union, cv2.MORPH_CLOSE, ell).astype(bool)
    joined = _fill(mask | cut | (bridged & cv2.dilate(cut.astype(np.uint8), ell).astype(bool)))
    contours, _ = cv2.findContours(
        joined.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE
    )
    outline = max(contours, key=cv2.contourArea).reshape(-1, 2).astype(np.float64)
    return ObjectRegion(
        joined, outline, blob, init, snake.iterations, snake.converged,
        method="active contour + cut-off parts",
        note=f"{int(cut.sum())} px of the background difference the contour cut off added back",
    )  # fmt: skip


#: With ``near_px``: the smallest blob taken, as a share of the largest.
NEAR_MIN_SHARE = 0.1


def _nearest_blob(labels: NDArray[Any], stats: NDArray[Any], near: NDArray[np.float64],
                  min_area: float, *, default: int) -> int:  # fmt: skip
    """The label of the blob (of at least ``min_area`` pixels) with a pixel nearest
    ``near`` (ties: the larger); ``default`` when none is large enough."""
    best, key = default, None
    for k in range(1, stats.shape[0]):
        area = int(stats[k, cv2.CC_STAT_AREA])
        if area < min_area:
            continue
        ys, xs = np.nonzero(labels == k)
        d = float(np.min(np.hypot(xs - near[0], ys - near[1])))
        if key is None or (d, -area) < key:
            best, key = k, (d, -area)
    return best


def _fill(mask: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """The largest connected part of ``mask`` with its holes filled."""
    m = mask.astype(np.uint8)
    contours, _ = cv2.findContours(m, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    out = np.zeros_like(m)
    if contours:
        cv2.drawContours(out, [max(contours, key=cv2.contourArea)], -1, 1, -1)
    return out.astype(bool)


#: A pixel darker than the background by one factor in every channel (within this spread
#: of the per-channel ratios), between :data:`SHADOW_MIN_RATIO` and :data:`SHADOW_MAX_RATIO`
#: of it, is the belt in shadow: light blocked, the belt's colour kept.
SHADOW_RATIO_SPREAD = 0.12
SHADOW_MIN_RATIO = 0.2
SHADOW_MAX_RATIO = 0.97


def cut_off_parts(
    image: NDArray[np.uint8],
    background: NDArray[np.uint8],
    blob: NDArray[np.bool_],
    mask: NDArray[np.bool_],
) -> NDArray[np.bool_]:
    """Parts of the background-difference ``blob`` the snake's region ``mask`` left out
    that are object, not shadow: a side nozzle or a handle joined to the body by a narrow
    neck, which the snake's tension (eq. 8's first-order term) cuts across as it shrinks.

    The blob outside the region, without the pixels that look like the belt in shadow
    (every channel darker than the background by about one factor), opened with a 7 px
    disc (the ring of a few pixels between the blob's blurred edge and the contour goes),
    keeping the pieces that touch the region and cover at least 0.5 % of it.
    """
    a = cv2.GaussianBlur(image, (5, 5), 1.2).astype(np.float32) + 1.0
    b = cv2.GaussianBlur(background, (5, 5), 1.2).astype(np.float32) + 1.0
    ratio = a / b
    shadow = (
        (ratio.max(axis=2) - ratio.min(axis=2) <= SHADOW_RATIO_SPREAD)
        & (ratio.max(axis=2) <= SHADOW_MAX_RATIO)
        & (ratio.min(axis=2) >= SHADOW_MIN_RATIO)
    )
    extra = (blob & ~mask & ~shadow).astype(np.uint8)
    extra = cv2.morphologyEx(
        extra, cv2.MORPH_OPEN, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (7, 7))
    )
    n, labels, stats, _ = cv2.connectedComponentsWithStats(extra, connectivity=8)
    if n <= 1:
        return np.zeros_like(mask, dtype=bool)
    near = cv2.dilate(mask.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    min_area = 0.005 * max(1, int(mask.sum()))
    keep = np.zeros(n, dtype=bool)
    for k in range(1, n):
        if stats[k, cv2.CC_STAT_AREA] >= min_area:
            keep[k] = bool(near[labels == k].any())
    return keep[labels]
