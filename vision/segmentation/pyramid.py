"""Coarse-to-fine image pyramids for the active contour and the level set.

A Gaussian pyramid (Burt and Adelson 1983) built with ``cv2.pyrDown`` halves the image per
level; the centre of coarse pixel ``x`` is the centre of fine pixel ``2 x``, so contours scale
by exactly 1/2 going down and 2 going up.  A segmentation solved on the coarsest level and
refined level by level travels the long distances where pixels are cheap and spends only a
few iterations at full resolution.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

from vision.segmentation.validation import MIN_IMAGE_SIDE_PX, check_int

__all__ = ["auto_levels", "gaussian_pyramid", "upsample_mask"]


def gaussian_pyramid(image: NDArray[np.float32], levels: int) -> list[NDArray[np.float32]]:
    """``[image, pyrDown(image), ...]``: ``levels + 1`` images, full resolution first.

    Raises ``ValueError`` when the coarsest level would be smaller than
    :data:`~vision.segmentation.validation.MIN_IMAGE_SIDE_PX` pixels on a side.
    """
    check_int(levels, "pyramid_levels", minimum=0)
    h, w = image.shape[:2]
    if min(h, w) >> levels < MIN_IMAGE_SIDE_PX:
        raise ValueError(
            f"pyramid_levels={levels} is too many for a {h}x{w} image: the coarsest level "
            f"would be under {MIN_IMAGE_SIDE_PX} px (at most {auto_levels((h, w), 1)} levels)"
        )
    out = [image]
    for _ in range(levels):
        out.append(np.asarray(cv2.pyrDown(out[-1], borderType=cv2.BORDER_REFLECT), out[-1].dtype))
    return out


def auto_levels(shape: tuple[int, ...], target_side_px: int = 256) -> int:
    """Levels that bring the longer image side to ``target_side_px`` or just below it.

    Never more than the image allows (coarsest side >= the minimum image side).
    """
    h, w = shape[:2]
    levels = 0
    while max(h, w) >> levels > target_side_px and min(h, w) >> (levels + 1) >= MIN_IMAGE_SIDE_PX:
        levels += 1
    return levels


def upsample_mask(mask: NDArray[np.bool_], shape: tuple[int, ...]) -> NDArray[np.bool_]:
    """Bring a coarse-level mask to the next finer level's ``shape`` (smooth, then threshold)."""
    up = cv2.pyrUp(mask.astype(np.float32), dstsize=(shape[1], shape[0]))
    return up > 0.5
