"""OpenCV's own detectors and descriptors behind VisionCell's interface: SIFT, ORB, AKAZE."""

from __future__ import annotations

import math

import cv2
import numpy as np

from vision.features.types import Features, Keypoints

__all__ = ["MAX_SMOOTH_PX", "keypoints_from_cv", "keypoints_to_cv", "opencv_features"]

_VERSION = f"opencv-{cv2.__version__}"
#: Largest pre-smoothing accepted, pixels (beyond it the finest octaves carry nothing).
MAX_SMOOTH_PX = 5.0


def keypoints_from_cv(kps: list[cv2.KeyPoint] | tuple[cv2.KeyPoint, ...]) -> Keypoints:
    """Convert OpenCV keypoints (angle in degrees, clockwise on screen) to :class:`Keypoints`."""
    if not kps:
        return Keypoints.empty()
    xy = np.array([k.pt for k in kps], dtype=np.float64)
    size = np.array([k.size for k in kps], dtype=np.float64)
    ang = np.array([k.angle for k in kps], dtype=np.float64)
    ang = np.where(ang < 0, 0.0, -np.deg2rad(ang))  # OpenCV uses -1 for "no orientation"
    resp = np.array([k.response for k in kps], dtype=np.float64)
    octv = np.array([k.octave for k in kps], dtype=np.int64)
    # SIFT packs octave, layer and scale into one int: keep the signed octave byte.
    octv = ((octv & 0xFF) ^ 0x80) - 0x80
    return Keypoints(xy, size, ang, resp, octv.astype(np.int32))


def keypoints_to_cv(kp: Keypoints) -> list[cv2.KeyPoint]:
    """Convert :class:`Keypoints` back to OpenCV keypoints (for drawing or OpenCV descriptors)."""
    return [
        cv2.KeyPoint(float(x), float(y), float(s), float(-np.rad2deg(a) % 360.0), float(r), int(o))
        for (x, y), s, a, r, o in zip(
            kp.xy, kp.size_px, kp.angle_rad, kp.response, kp.octave, strict=True
        )
    ]


def _create(
    method: str, max_features: int | None, threshold: float | None
) -> tuple[cv2.Feature2D, bool]:
    # cv2's stubs do not declare the *_create factories at module level.
    if method == "sift":
        kw = {} if threshold is None else {"contrastThreshold": threshold}
        return cv2.SIFT_create(nfeatures=max_features or 0, **kw), False  # type: ignore[attr-defined]
    if method == "orb":
        return cv2.ORB_create(nfeatures=max_features or 1000), True  # type: ignore[attr-defined]
    if method == "akaze":
        kw = {} if threshold is None else {"threshold": threshold}
        return cv2.AKAZE_create(**kw), True  # type: ignore[attr-defined]
    raise ValueError(f"unknown OpenCV method {method!r}")


def opencv_features(
    grey: np.ndarray,
    method: str,
    *,
    max_features: int | None = None,
    threshold: float | None = None,
    mask: np.ndarray | None = None,
    smooth_px: float = 0.0,
) -> Features:
    """Detect and describe with OpenCV's SIFT (Lowe 2004), ORB (Rublee et al. 2011) or AKAZE
    (Alcantarilla et al. 2013).

    Parameters
    ----------
    grey : ndarray of shape (H, W), uint8
    method : {"sift", "orb", "akaze"}
    max_features : int, optional
        Keep at most this many of the strongest keypoints (AKAZE: trimmed after detection).
    threshold : float, optional
        Detector threshold (SIFT ``contrastThreshold``, AKAZE ``threshold``).
    mask : ndarray of shape (H, W), optional
        Non-zero where keypoints may be detected.
    smooth_px : float
        Standard deviation of a Gaussian blur applied to the image before detection and
        description, pixels (0 = none, at most :data:`MAX_SMOOTH_PX`). SIFT assumes an input
        already blurred by 0.5 px and doubles it for its first octave (Lowe 2004, section
        3.3); an image without optical blur (a render without anti-aliasing) or with sensor
        noise near the detector threshold breaks that assumption, and the first octave's
        keypoints then follow the pixel grid and the noise rather than the object: a part
        rotated on the belt no longer finds them.
    """
    if (
        isinstance(smooth_px, bool)
        or not isinstance(smooth_px, int | float)
        or not (math.isfinite(smooth_px) and 0.0 <= smooth_px <= MAX_SMOOTH_PX)
    ):
        raise ValueError(f"smooth_px must be a number in [0, {MAX_SMOOTH_PX:g}], got {smooth_px!r}")
    if smooth_px > 0.0:
        grey = cv2.GaussianBlur(grey, (0, 0), float(smooth_px))
    det, binary = _create(method, max_features, threshold)
    m = None if mask is None else (np.asarray(mask) > 0).astype(np.uint8)
    kps, desc = det.detectAndCompute(grey, m)
    kps = list(kps)
    if desc is None or not kps:
        width = 32 if binary else 128
        return Features(
            Keypoints.empty(),
            np.zeros((0, width), np.uint8 if binary else np.float32),
            method,
            _VERSION,
            binary,
            grey.shape[:2],
        )
    if max_features and len(kps) > max_features:
        order = np.argsort([-k.response for k in kps])[:max_features]
        kps = [kps[i] for i in order]
        desc = desc[order]
    return Features(keypoints_from_cv(kps), desc, method, _VERSION, binary, grey.shape[:2])
