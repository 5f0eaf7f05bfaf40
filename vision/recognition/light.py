"""The light of a query against the light the views were taught under, from the belt.

A change of the lamps (a dimmed or a warmer light) changes the grey contrast of a part in a
way its descriptors do not undo: the detector threshold is absolute, so a dim view loses
keypoints, and the grey level is a weighted sum of the channels, so a colour cast changes
the contrast between a part's differently coloured surfaces.  The empty belt round the
object is a surface the camera sees in every top view, taught or queried; under the
diagonal (von Kries) model of a light change each channel of every surface is scaled by the
same factor, so the per-channel ratio of the belt's colour when taught to its colour now is
the gain that brings the query back to the taught light (Finlayson, Drew and Funt, "Diagonal
transforms suffice for color constancy", ICCV 1993, for when a diagonal map is enough).

* :func:`surround_colour`: the median colour of the pixels round an object's region (the
  belt), leaving out clipped and near-black pixels, whose ratios say nothing of the light.
* :func:`light_gain`: the per-channel gain from a reference colour and the current one,
  bounded, or None when no correction is needed or it cannot be trusted.
* :func:`apply_gain`: the gain applied to an 8-bit image (a lookup per channel).
"""

from __future__ import annotations

import math

import cv2
import numpy as np
from numpy.typing import NDArray

from vision.errors import InvalidInput, VisionCellError

__all__ = [
    "GAIN_DEADBAND",
    "MAX_GAIN",
    "LightChanged",
    "apply_gain",
    "light_gain",
    "surround_colour",
]

#: Gap between the object's region and the pixels taken for the belt, pixels (a shadow or
#: a blurred edge round the object is not the belt).
SURROUND_GAP_PX = 9
#: Fewest usable surround pixels for a colour.
MIN_SURROUND_PX = 400
#: A pixel with any channel at or above this is clipped (its ratio is not the light's).
CLIP_LEVEL = 250
#: A pixel whose channels sum below this is too dark for a ratio (noise, quantisation).
DARK_SUM = 24
#: A channel gain beyond ``[1 / MAX_GAIN, MAX_GAIN]`` is refused (the light is not the one
#: the views were taught under in a way a gain can undo: teach again, or grab a background).
MAX_GAIN = 4.0
#: Every channel within this of 1: no correction (noise in the two medians, not the light).
GAIN_DEADBAND = 0.03


class LightChanged(VisionCellError):
    """The light changed since the views were taught beyond what a per-channel gain undoes."""

    code = "light_changed"


def surround_colour(
    image: NDArray[np.uint8], mask: NDArray[np.bool_] | NDArray[np.uint8] | None
) -> NDArray[np.float64] | None:
    """Median RGB of the pixels outside ``mask`` (dilated by :data:`SURROUND_GAP_PX`) of
    an ``(H, W, 3)`` 8-bit image, or None for a grey image, no mask, or fewer than
    :data:`MIN_SURROUND_PX` usable pixels.  Clipped pixels (any channel >=
    :data:`CLIP_LEVEL`) and near-black ones are left out."""
    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] != 3 or mask is None:
        return None
    if img.dtype != np.uint8:
        raise InvalidInput(f"the image must be 8-bit, got {img.dtype}")
    m = np.asarray(mask)
    if m.shape != img.shape[:2]:
        raise InvalidInput(f"the mask is {m.shape}, the image {img.shape[:2]}")
    k = 2 * SURROUND_GAP_PX + 1
    grown = np.asarray(cv2.dilate(m.astype(bool).astype(np.uint8), np.ones((k, k), np.uint8)))
    inside = grown.astype(bool)
    usable = (
        ~inside & (img.max(axis=2) < CLIP_LEVEL) & (img.sum(axis=2, dtype=np.int32) >= DARK_SUM)
    )
    if int(usable.sum()) < MIN_SURROUND_PX:
        return None
    return np.median(img[usable], axis=0).astype(np.float64)


def light_gain(
    reference: NDArray[np.float64] | None, current: NDArray[np.float64] | None
) -> NDArray[np.float64] | None:
    """Per-channel gain taking ``current`` (the belt's colour now) to ``reference`` (its
    colour when taught), or None when either is unknown or every channel is within
    :data:`GAIN_DEADBAND` of 1.

    Raises
    ------
    InvalidInput
        A colour that is not three finite values above zero.
    LightChanged
        A gain outside ``[1 / MAX_GAIN, MAX_GAIN]``: the light changed beyond what a gain
        undoes.
    """
    if reference is None or current is None:
        return None
    ref = np.asarray(reference, dtype=np.float64).reshape(-1)
    cur = np.asarray(current, dtype=np.float64).reshape(-1)
    for name, c in (("reference", ref), ("current", cur)):
        if c.shape != (3,) or not np.all(np.isfinite(c)) or np.any(c <= 0.0):
            raise InvalidInput(f"the {name} belt colour must be three finite values > 0, got {c!r}")
    gain = ref / cur
    if np.any(gain > MAX_GAIN) or np.any(gain < 1.0 / MAX_GAIN):
        raise LightChanged(
            f"the light changed beyond a gain of {MAX_GAIN:g} per channel since the views "
            f"were taught (gain {np.round(gain, 3).tolist()}): check the lamps, or teach again"
        )
    if np.all(np.abs(gain - 1.0) <= GAIN_DEADBAND):
        return None
    return gain


def apply_gain(image: NDArray[np.uint8], gain: NDArray[np.float64] | None) -> NDArray[np.uint8]:
    """``image`` (8-bit RGB) with each channel scaled by ``gain`` and clipped to 255; the
    image itself when ``gain`` is None."""
    if gain is None:
        return image
    img = np.asarray(image)
    g = np.asarray(gain, dtype=np.float64).reshape(-1)
    if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
        raise InvalidInput(f"apply_gain takes an 8-bit RGB image, got {img.dtype} {img.shape}")
    if g.shape != (3,) or not all(math.isfinite(v) and 0.0 < v <= MAX_GAIN for v in g):
        raise InvalidInput(f"the gain must be three values in (0, {MAX_GAIN:g}], got {g!r}")
    levels = np.arange(256, dtype=np.float64)
    lut = np.clip(np.rint(levels[None, :] * g[:, None]), 0, 255).astype(np.uint8)
    channels = [cv2.LUT(np.ascontiguousarray(img[..., c]), lut[c]) for c in range(3)]
    return np.dstack(channels)
