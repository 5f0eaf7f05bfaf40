"""The object's region in a view: the chapter's active contour (section 3.2, eqs. 6-11)
initialised from the difference with the empty-belt background.

1. Foreground: the per-pixel largest channel difference between the (slightly blurred)
   image and the background of the same viewpoint, thresholded at ``min_diff`` grey levels
   (a fixed level: a dark part on the dark belt under dimmed light can fall below it),
   opened and closed, and the largest connected blob kept with its holes filled.  This is where the object is, roughly: shadows and the belt seen through holes
   move its edge by a few pixels.
2. Initial contour: the blob's convex hull pushed out by ``margin_px`` along its normals
   (the loose contour around the object that the chapter's operator would draw).
3. The snake (:func:`vision.segmentation.active_contour`, eq. 8 with the edge energy of
   eq. 11) shrinks from there under a small balloon pressure (Cohen 1991) that fades on
   edges, and stops on the object's outline.  Its inside is the object's mask.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from vision.errors import VisionCellError
from vision.segmentation import active_contour, iou, mask_from_contour, resample_closed

__all__ = ["ObjectRegion", "SegmentationFailed", "foreground_mask", "segment_object"]


class SegmentationFailed(VisionCellError):
    """No object could be separated from the background."""

    code = "segmentation_failed"
    http_status = 422


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
) -> NDArray[np.bool_]:
    """The largest blob that differs from ``background`` (step 1), holes filled.

    Parameters
    ----------
    image, background : ndarray of shape (H, W, 3), uint8
        The view with the object, and the same view with the belt empty.
    min_diff : int
        Smallest channel difference (grey levels) counted as foreground.
    min_area_frac : float
        Smallest blob, as a fraction of the image area.

    Raises
    ------
    SegmentationFailed
        Nothing differs enough from the background.
    """
    _check_pair(image, background)
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
    area = int(stats[k, cv2.CC_STAT_AREA])
    if area < min_area_frac * image.shape[0] * image.shape[1]:
        raise SegmentationFailed(
            f"the largest change from the background covers {area} px, under "
            f"{min_area_frac:.1%} of the image: is the object at the station?"
        )
    blob = (labels == k).astype(np.uint8)
    contours, _ = cv2.findContours(blob, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    filled = np.zeros_like(blob)
    cv2.drawContours(filled, contours, -1, 1, -1)
    return filled.astype(bool)


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

    Raises
    ------
    SegmentationFailed
        Nothing differs enough from the background.
    """
    if not 0.0 <= margin_px <= 100.0:
        raise ValueError(f"margin_px must be in [0, 100], got {margin_px!r}")
    blob = foreground_mask(image, background)
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
    return ObjectRegion(mask, snake.contour, blob, init, snake.iterations, snake.converged)
