"""One entry point for every detector/descriptor: ``extract(image, method, **options)``."""

from __future__ import annotations

import importlib
from collections.abc import Callable

import cv2
import numpy as np

from vision.features.types import Features

__all__ = ["COLOUR_METHODS", "METHODS", "RGB_METHODS", "extract", "grey_from_image"]

# method id -> "module:function". Each function takes the image (grey uint8 (H, W), or RGB
# uint8 (H, W, 3) for the colour methods) and keyword options, and returns Features.
_REGISTRY: dict[str, str] = {
    "sift": "vision.features.opencv:opencv_features",
    "orb": "vision.features.opencv:opencv_features",
    "akaze": "vision.features.opencv:opencv_features",
    "surf": "vision.features.surf:surf_features",
    "pca-sift": "vision.features.pcasift:pca_sift_features",
    "gloh": "vision.features.gloh:gloh_features",
    "color-sift": "vision.features.colour:colour_features",
    "color-surf": "vision.features.colour:colour_features",
    "opponent-sift": "vision.features.opponent:opponent_sift_features",
}

#: Methods that need the RGB image (the chapter's colour-invariant descriptor, eqs. 15-19).
COLOUR_METHODS = frozenset({"color-sift", "color-surf"})
#: Methods that need the RGB image but are not the chapter's descriptor (baselines).
RGB_METHODS = frozenset({"opponent-sift"})
#: Every method id ``extract`` accepts.
METHODS = tuple(_REGISTRY)
_OPENCV = frozenset({"sift", "orb", "akaze"})


def grey_from_image(image: np.ndarray) -> np.ndarray:
    """Greyscale uint8 view of an RGB (H, W, 3) or grey (H, W) uint8 image (ITU-R BT.601)."""
    if image.ndim == 2:
        return image
    return cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)


def _check_image(image: np.ndarray, method: str) -> np.ndarray:
    if not isinstance(image, np.ndarray):
        raise ValueError(f"image must be a numpy array, got {type(image).__name__}")
    if image.dtype != np.uint8 and not (image.dtype == np.uint16 and method in COLOUR_METHODS):
        raise ValueError(
            f"image must be uint8 (uint16 linear RGB only for the colour methods), got dtype "
            f"{image.dtype} for {method!r}"
        )
    if image.ndim not in (2, 3) or (image.ndim == 3 and image.shape[2] != 3):
        raise ValueError(f"image must have shape (H, W) or (H, W, 3), got {image.shape}")
    if min(image.shape[:2]) < 16:
        raise ValueError(f"image of shape {image.shape} is too small for features (min 16 px)")
    if method in COLOUR_METHODS | RGB_METHODS and image.ndim != 3:
        raise ValueError(f"method {method!r} needs an RGB image (H, W, 3), got {image.shape}")
    return np.ascontiguousarray(image)


def _resolve(method: str) -> Callable[..., Features]:
    module, func = _REGISTRY[method].split(":")
    return getattr(importlib.import_module(module), func)


def extract(image: np.ndarray, method: str = "sift", **options) -> Features:
    """Detect keypoints and compute descriptors with the named method.

    Parameters
    ----------
    image : ndarray of shape (H, W) or (H, W, 3), uint8
        Grey or RGB image (RGB order, as everywhere in VisionCell). Grey methods convert RGB
        input to grey; the colour methods need RGB and also take uint16 linear sensor values
        (options ``transfer``, ``white_level``, ``noise_floor``, ``saturation``, ``layout``:
        see :func:`vision.features.colour.colour_features`; ``transfer="srgb"`` linearises a
        gamma-encoded 8-bit image before the colour ratios).
    method : str
        One of :data:`METHODS`: ``"sift"`` (Lowe 2004), ``"orb"``, ``"akaze"`` (OpenCV),
        ``"surf"`` (Bay et al. 2008, written here), ``"pca-sift"`` (Ke and Sukthankar 2004),
        ``"gloh"`` (Mikolajczyk and Schmid 2005), ``"color-sift"`` / ``"color-surf"`` (the
        chapter's colour-invariant descriptor, equations 15-19), ``"opponent-sift"`` (van de
        Sande, Gevers and Snoek, TPAMI 2010; a colour baseline, RGB uint8).
    **options
        Method-specific keyword options (``max_features``, ``threshold``, ``mask``,
        ``upright``, ``basis`` ...), documented on each method's function.

    Returns
    -------
    Features
        Frozen keypoints and descriptors, with the method id and descriptor version.

    Raises
    ------
    ValueError
        Unknown method, or an image of the wrong dtype, shape or size.
    """
    if method not in _REGISTRY:
        raise ValueError(f"unknown feature method {method!r}; choose one of {', '.join(METHODS)}")
    image = _check_image(image, method)
    func = _resolve(method)
    if method in _OPENCV:
        return func(grey_from_image(image), method, **options)
    if method in COLOUR_METHODS:
        return func(image, base=method.removeprefix("color-"), **options)
    if method in RGB_METHODS:
        return func(image, **options)
    return func(grey_from_image(image), **options)
