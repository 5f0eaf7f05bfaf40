"""SURF, written here because OpenCV's wheels lack it (the "nonfree" xfeatures2d module).

Bay, Ess, Tuytelaars and Van Gool, "Speeded-Up Robust Features (SURF)", Computer Vision and
Image Understanding 110(3), 346-359, 2008 (ECCV 2006). Detector in
:mod:`vision.features.surf_detect`, orientation and descriptor in
:mod:`vision.features.surf_describe`; the hot loops are numba-compiled (cached on disk; call
:func:`warm_up` once at start-up to pay the first-call compilation outside a request).

Keypoint conventions
--------------------
A box filter of size ``L`` corresponds to the Gaussian scale ``s = 1.2 L / 9`` (paper section
3.2). ``Keypoints.size_px`` is the side of the descriptor window, ``size_px = 20 s`` (so the
smallest keypoints, ``L = 9``, have ``size_px = 24``); :func:`surf_describe` reads the scale back
as ``s = size_px / 20``. OpenCV's old SURF reported ``KeyPoint.size = L = 7.5 s`` instead:
multiply ours by ``0.375`` to compare. ``angle_rad`` is counter-clockwise on screen, as for every
VisionCell keypoint, ``octave`` is the detector octave (0 = filters 9..27).
"""

from __future__ import annotations

import numbers

import cv2
import numpy as np

from vision.features.surf_describe import (
    WINDOW_IN_S,
    describe_integral,
    describe_integral_channels,
    orientation_integral,
)
from vision.features.surf_detect import BASE_SCALE, detect_hessian, integral_image
from vision.features.types import Features, Keypoints

__all__ = [
    "DEFAULT_THRESHOLD",
    "SURF_VERSION",
    "surf_describe",
    "surf_describe_channels",
    "surf_features",
    "surf_keypoints",
    "surf_orientation",
    "warm_up",
]

#: Descriptor version: changes whenever stored SURF descriptors stop being comparable.
SURF_VERSION = "visioncell-surf-1"
#: Default threshold on det(H_approx) for a uint8 image (values 0..255), see surf_features.
DEFAULT_THRESHOLD = 40.0
_MAX_OCTAVES = 6


def _check_image(image: np.ndarray, name: str, dtypes: tuple[type, ...]) -> np.ndarray:
    if not isinstance(image, np.ndarray):
        raise ValueError(f"{name} must be a numpy array, got {type(image).__name__}")
    if image.ndim != 2:
        raise ValueError(f"{name} must be a single-channel (H, W) array, got shape {image.shape}")
    if image.dtype.type not in dtypes:
        allowed = ", ".join(np.dtype(d).name for d in dtypes)
        raise ValueError(f"{name} must have dtype {allowed}, got {image.dtype}")
    if min(image.shape) < 16:
        raise ValueError(f"{name} of shape {image.shape} is too small for SURF (min 16 px)")
    if image.dtype.kind == "f" and not np.all(np.isfinite(image)):
        raise ValueError(f"{name} contains NaN or infinite values")
    return image


def _keypoint_scales(keypoints: Keypoints) -> np.ndarray:
    s = keypoints.size_px / WINDOW_IN_S
    if len(s) and not np.all(np.isfinite(s) & (s > 0)):
        bad = keypoints.size_px[~(np.isfinite(s) & (s > 0))][0]
        raise ValueError(f"keypoints.size_px must be positive and finite, got {bad}")
    if len(s) and not np.all(np.isfinite(keypoints.xy)):
        raise ValueError("keypoints.xy contains NaN or infinite values")
    return s


def surf_describe(
    image: np.ndarray,
    keypoints: Keypoints,
    *,
    upright: bool = False,
    extended: bool = False,
    coarse: bool = False,
) -> np.ndarray:
    """SURF descriptors at given keypoints, using their scale and orientation.

    Parameters
    ----------
    image : ndarray of shape (H, W), uint8, float32 or float64
        Single-channel image of any value range (for instance a log colour-ratio image of the
        chapter's colour-invariant descriptor, eqs. 15-17); it is not rescaled: the descriptor
        is normalised to unit length, so it does not depend on the image's gain.
    keypoints : Keypoints
        Positions in pixels of ``image``; scale ``s = size_px / 20``; orientation
        ``angle_rad`` (counter-clockwise on screen).
    upright : bool
        Ignore ``angle_rad`` and describe in the image axes (U-SURF, paper section 4.2).
    extended : bool
        128-dimensional descriptor (sums split by the sign of the other response).
    coarse : bool
        Sample the 20 s window on a 10 x 10 grid spaced 2 s with Haar boxes of side 4 s
        instead of 20 x 20 spaced s with side 2 s: a quarter of the work, for smooth images
        (the colour-ratio images of the joint colour descriptor).

    Returns
    -------
    ndarray of shape (N, 64) or (N, 128), float32
        Unit-length descriptors (all zero where the image is constant under the window).

    Raises
    ------
    ValueError
        Image not 2-D, of another dtype, too small or non-finite; keypoint sizes not positive.

    References
    ----------
    Bay et al., CVIU 110(3), 2008, section 4.2.
    """
    image = _check_image(image, "image", (np.uint8, np.float32, np.float64))
    if not isinstance(keypoints, Keypoints):
        raise ValueError(f"keypoints must be Keypoints, got {type(keypoints).__name__}")
    dim = 128 if extended else 64
    if len(keypoints) == 0:
        return np.zeros((0, dim), dtype=np.float32)
    scales = _keypoint_scales(keypoints)
    ii = integral_image(image)
    theta = np.zeros(len(keypoints)) if upright else -keypoints.angle_rad
    return describe_integral(ii, keypoints.xy, scales, theta, extended=extended, coarse=coarse)


def surf_describe_channels(
    images: np.ndarray,
    keypoints: Keypoints,
    *,
    live: np.ndarray | None = None,
    upright: bool = False,
    extended: bool = False,
    coarse: bool = False,
) -> np.ndarray:
    """:func:`surf_describe` of several images of one size at the same keypoints, in one pass.

    The sample grid and Haar boxes of each keypoint are computed once and read from all the
    images' integral images (one interleaved table); the result of each image equals
    :func:`surf_describe` of it (the same arithmetic). For the m-images of the joint colour
    descriptor.

    Parameters
    ----------
    images : ndarray of shape (C, H, W), float32 or float64
        Finite single-channel images, 1 <= C <= 8.
    keypoints : Keypoints
    live : ndarray of shape (N, C), bool, optional
        Which (keypoint, image) descriptors to compute; the others are left at 0 (default: all).
    upright, extended, coarse
        As :func:`surf_describe`.

    Returns
    -------
    ndarray of shape (N, C, 64) or (N, C, 128), float32
    """
    if not isinstance(images, np.ndarray) or images.ndim != 3 or not 1 <= len(images) <= 8:
        raise ValueError(
            f"images must be a (C, H, W) array with 1 <= C <= 8, got {getattr(images, 'shape', images)}"
        )
    for k in range(len(images)):
        _check_image(images[k], f"images[{k}]", (np.float32, np.float64))
    if not isinstance(keypoints, Keypoints):
        raise ValueError(f"keypoints must be Keypoints, got {type(keypoints).__name__}")
    dim = 128 if extended else 64
    if len(keypoints) == 0:
        return np.zeros((0, len(images), dim), dtype=np.float32)
    if live is not None:
        live = np.asarray(live)
        if live.shape != (len(keypoints), len(images)) or live.dtype != np.bool_:
            raise ValueError(
                f"live must be a bool array of shape {(len(keypoints), len(images))}, got "
                f"{live.dtype} {live.shape}"
            )
    scales = _keypoint_scales(keypoints)
    # One interleaved (H + 1, W + 1, C) summed-area table in float64 (OpenCV's integral:
    # the same sums as integral_image per channel, several times faster).
    ii = cv2.integral(np.ascontiguousarray(np.moveaxis(images, 0, -1)), sdepth=cv2.CV_64F)
    if ii.ndim == 2:  # OpenCV drops a single channel's axis
        ii = ii[..., None]
    theta = np.zeros(len(keypoints)) if upright else -keypoints.angle_rad
    return describe_integral_channels(
        ii, keypoints.xy, scales, theta, live=live, extended=extended, coarse=coarse
    )


def surf_orientation(image: np.ndarray, keypoints: Keypoints) -> np.ndarray:
    """Haar-wavelet orientation (paper section 4.1) of keypoints, radians counter-clockwise on
    screen, in ``(-pi, pi]``.

    Parameters
    ----------
    image : ndarray of shape (H, W), uint8, float32 or float64
    keypoints : Keypoints
        Positions and sizes (``s = size_px / 20``); their angles are ignored.

    Returns
    -------
    ndarray of shape (N,), float64
    """
    image = _check_image(image, "image", (np.uint8, np.float32, np.float64))
    if len(keypoints) == 0:
        return np.zeros(0)
    scales = _keypoint_scales(keypoints)
    return -orientation_integral(integral_image(image), keypoints.xy, scales)


def surf_features(
    grey: np.ndarray,
    *,
    threshold: float = DEFAULT_THRESHOLD,
    n_octaves: int = 4,
    upright: bool = False,
    extended: bool = False,
    max_features: int | None = None,
    mask: np.ndarray | None = None,
) -> Features:
    """Detect SURF keypoints (Fast-Hessian) and compute their SURF descriptors.

    Parameters
    ----------
    grey : ndarray of shape (H, W), uint8
        Grey image.
    threshold : float
        Minimum determinant of the approximated Hessian, ``Dxx Dyy - (0.9 Dxy)^2`` with each
        box response divided by the filter area ``L^2``, for image values 0..255 (paper eq. 4).
        The default, 40, gives about as many keypoints as OpenCV's SIFT on the Oxford images;
        OpenCV's old ``hessianThreshold`` used the same unit (its usual 100..500 keep fewer).
    n_octaves : int
        Octaves of the scale space, 1..6 (filter sizes 9..27, 15..51, 27..99,
        51..195, ...); octaves whose filters do not fit in the image are skipped.
    upright : bool
        U-SURF: no orientation assignment, descriptors in the image axes, ``angle_rad = 0``.
    extended : bool
        128-dimensional descriptors instead of 64.
    max_features : int, optional
        Keep at most this many keypoints, the strongest (largest determinant) first.
    mask : ndarray of shape (H, W), optional
        Keypoints are kept only where the mask is non-zero.

    Returns
    -------
    Features
        Method ``"surf"``, version :data:`SURF_VERSION`, float32 unit descriptors;
        ``size_px = 20 s`` with ``s = 1.2 L / 9`` (see the module docstring).

    Raises
    ------
    ValueError
        Image not (H, W) uint8 or smaller than 16 px; threshold negative or not finite;
        n_octaves outside 1..6; max_features not a positive integer; mask of another shape.

    References
    ----------
    Bay, Ess, Tuytelaars and Van Gool, "Speeded-Up Robust Features (SURF)", CVIU 110(3),
    346-359, 2008.

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> f = surf_features(rng.integers(0, 256, (120, 160), dtype=np.uint8))
    >>> f.dim
    64
    """
    ii, xy, scales, theta, strength, octave = _detect(
        grey, threshold, n_octaves, upright, max_features, mask
    )
    desc = describe_integral(ii, xy, scales, theta, extended=extended)
    kp = Keypoints(xy, WINDOW_IN_S * scales, -theta + 0.0, strength, octave)
    return Features(kp, desc, "surf", SURF_VERSION, False, np.shape(grey))


def surf_keypoints(
    grey: np.ndarray,
    *,
    threshold: float = DEFAULT_THRESHOLD,
    n_octaves: int = 4,
    upright: bool = False,
    max_features: int | None = None,
    mask: np.ndarray | None = None,
) -> Keypoints:
    """The keypoints of :func:`surf_features` (detection and orientation) without their
    descriptors, for callers that describe other images at them (the colour descriptor).

    Parameters and errors as :func:`surf_features`.
    """
    _, xy, scales, theta, strength, octave = _detect(
        grey, threshold, n_octaves, upright, max_features, mask
    )
    return Keypoints(xy, WINDOW_IN_S * scales, -theta + 0.0, strength, octave)


def _detect(
    grey: np.ndarray,
    threshold: float,
    n_octaves: int,
    upright: bool,
    max_features: int | None,
    mask: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Validate, detect (Fast-Hessian), filter, sort strongest first and orient: the integral
    image, positions (N, 2), scales s, orientations (clockwise, the kernels' convention),
    Hessian responses and octaves."""
    grey = _check_image(grey, "grey", (np.uint8,))
    if not isinstance(threshold, numbers.Real) or not np.isfinite(threshold) or threshold < 0:
        raise ValueError(f"threshold must be a finite number >= 0, got {threshold!r}")
    if (
        isinstance(n_octaves, bool)
        or not isinstance(n_octaves, numbers.Integral)
        or not 1 <= n_octaves <= _MAX_OCTAVES
    ):
        raise ValueError(f"n_octaves must be an integer in 1..{_MAX_OCTAVES}, got {n_octaves!r}")
    if max_features is not None and (
        isinstance(max_features, bool)
        or not isinstance(max_features, numbers.Integral)
        or max_features < 1
    ):
        raise ValueError(f"max_features must be a positive integer or None, got {max_features!r}")
    if mask is not None:
        mask = np.asarray(mask)
        if mask.shape != grey.shape:
            raise ValueError(f"mask must have the image's shape {grey.shape}, got {mask.shape}")

    ii = integral_image(grey)
    pts, octave = detect_hessian(ii, int(n_octaves), float(threshold))
    height, width = grey.shape
    keep = (pts[:, 0] >= 0) & (pts[:, 0] <= width - 1) & (pts[:, 1] >= 0)
    keep &= pts[:, 1] <= height - 1
    if mask is not None:
        col = np.clip(np.rint(pts[:, 0]).astype(np.int64), 0, width - 1)
        row = np.clip(np.rint(pts[:, 1]).astype(np.int64), 0, height - 1)
        keep &= mask[row, col] != 0
    pts, octave = pts[keep], octave[keep]
    order = np.argsort(-pts[:, 3], kind="stable")
    if max_features is not None:
        order = order[:max_features]
    pts, octave = pts[order], octave[order]

    xy = pts[:, :2]
    scales = BASE_SCALE * pts[:, 2] / 9.0
    theta = np.zeros(len(pts)) if upright or len(pts) == 0 else orientation_integral(ii, xy, scales)
    return ii, xy, scales, theta, pts[:, 3], octave


def warm_up() -> None:
    """Compile (or load from numba's on-disk cache) every SURF kernel on a tiny image, so the
    first real call does not pay the JIT cost (3-9 s with an empty cache, well under 1 s from
    numba's cache in __pycache__)."""
    rng = np.random.default_rng(0)
    img = rng.integers(0, 256, (64, 64), dtype=np.uint8)
    f = surf_features(img, threshold=0.0, n_octaves=1)
    surf_features(img, threshold=0.0, n_octaves=1, upright=True, extended=True)
    surf_describe(img.astype(np.float32), f.keypoints)
