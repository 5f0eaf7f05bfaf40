"""Input checks shared by the segmentation functions.

Image problems raise :class:`~vision.errors.ImageError` (a ``ValueError``); bad tuning
values and contours raise ``ValueError``.  Every message names the parameter and quotes the
value, so that a caller can tell what to change.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vision.errors import ImageError

__all__ = [
    "MIN_IMAGE_SIDE_PX",
    "check_contour",
    "check_image",
    "check_int",
    "check_nonnegative",
    "check_positive",
]

#: Smallest image side the segmentation accepts; below it no contour fits a smoothing kernel.
MIN_IMAGE_SIDE_PX = 8

_SCALE = {np.dtype(np.uint8): 1.0 / 255.0, np.dtype(np.uint16): 1.0 / 65535.0}


def check_image(
    image: Any, name: str = "image", *, min_side_px: int = MIN_IMAGE_SIDE_PX
) -> NDArray[np.float32]:
    """Validate a grey or colour image and return it as float32 in [0, 1].

    Parameters
    ----------
    image : ndarray of shape (H, W), (H, W, 1) or (H, W, 3)
        uint8 (0..255), uint16 (0..65535), or float32/float64 already in [0, 1].
    name : str
        Parameter name for the messages.
    min_side_px : int
        Smallest accepted height and width.

    Returns
    -------
    ndarray of shape (H, W) or (H, W, 3), float32, C-contiguous
    """
    if not isinstance(image, np.ndarray):
        raise ImageError(f"{name} must be a numpy array, got {type(image).__name__}")
    if image.size == 0:
        raise ImageError(f"{name} is empty: shape {image.shape}")
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[:, :, 0]
    if not (image.ndim == 2 or (image.ndim == 3 and image.shape[2] == 3)):
        raise ImageError(f"{name} must have shape (H, W) or (H, W, 3), got {image.shape}")
    h, w = image.shape[:2]
    if min(h, w) < min_side_px:
        raise ImageError(
            f"{name} is too small: {h}x{w} pixels, need at least {min_side_px} per side"
        )
    dt = image.dtype
    if dt in _SCALE:
        out = image.astype(np.float32) * np.float32(_SCALE[dt])
    elif dt in (np.float32, np.float64):
        if not np.all(np.isfinite(image)):
            raise ImageError(f"{name} contains NaN or infinity")
        lo, hi = float(image.min()), float(image.max())
        if lo < -1e-6 or hi > 1.0 + 1e-6:
            raise ImageError(f"{name} of dtype {dt} must lie in [0, 1], got values in [{lo}, {hi}]")
        out = image.astype(np.float32)
    else:
        raise ImageError(f"{name} must be uint8, uint16, float32 or float64, got dtype {dt}")
    return np.ascontiguousarray(out)


def check_contour(
    contour: ArrayLike,
    shape: tuple[int, ...],
    name: str = "init",
    *,
    min_points: int = 5,
    margin_px: float = 0.5,
) -> NDArray[np.float64]:
    """Validate a closed contour of ``(x, y)`` pixel positions inside an image of ``shape``.

    Parameters
    ----------
    contour : array_like of shape (N, 2)
        ``(x, y)`` = (column, row) pixel positions, the first point not repeated at the end.
    shape : tuple
        The image shape ``(H, W[, C])``.
    min_points : int
        Fewest points accepted (the pentadiagonal snake matrix needs five).
    margin_px : float
        How far outside the pixel centres ``[0, W-1] x [0, H-1]`` a point may lie.
    """
    c = np.asarray(contour, dtype=np.float64)
    if c.ndim != 2 or c.shape[1] != 2:
        raise ValueError(f"{name} must have shape (N, 2) of (x, y) points, got {c.shape}")
    if c.shape[0] < min_points:
        raise ValueError(f"{name} needs at least {min_points} points, got {c.shape[0]}")
    if not np.all(np.isfinite(c)):
        row = int(np.flatnonzero(~np.all(np.isfinite(c), axis=1))[0])
        raise ValueError(f"{name} contains NaN or infinity, e.g. row {row}: {c[row].tolist()}")
    h, w = shape[:2]
    outside = (
        (c[:, 0] < -margin_px)
        | (c[:, 0] > w - 1 + margin_px)
        | (c[:, 1] < -margin_px)
        | (c[:, 1] > h - 1 + margin_px)
    )
    if np.any(outside):
        row = int(np.flatnonzero(outside)[0])
        raise ValueError(
            f"{name} has {int(outside.sum())} point(s) outside the {w}x{h} image "
            f"(x in [0, {w - 1}], y in [0, {h - 1}]), e.g. row {row}: {c[row].tolist()}"
        )
    return c


def check_positive(value: float, name: str) -> float:
    """Return ``value`` as float if it is finite and > 0, else raise ``ValueError``."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a positive number, got {value!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise ValueError(f"{name} must be a positive number, got {value!r}")
    return v


def check_nonnegative(value: float, name: str) -> float:
    """Return ``value`` as float if it is finite and >= 0, else raise ``ValueError``."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number >= 0, got {value!r}") from None
    if not (math.isfinite(v) and v >= 0):
        raise ValueError(f"{name} must be a number >= 0, got {value!r}")
    return v


def check_int(value: int, name: str, *, minimum: int) -> int:
    """Return ``value`` if it is an int >= ``minimum``, else raise ``ValueError``."""
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)
