"""The joint layout of the colour descriptor (issue 17): the grey base descriptor followed by
the descriptors of noise-aware m-images, each weighted by its colour contrast.

Why (measured on the real illumination pairs of ``benchmarks.registration``): the chapter's
m-image descriptors alone (equations 15-17) lose to the grey base under real light changes,
because (a) the log ratios of dark pixels are mostly noise, (b) SIFT and SURF normalise each
m-image descriptor to unit length, so a window with no colour edge -- pure noise -- weighs as
much as one with strong colour edges, and (c) where lamps of different colours light a scene
from different sides, the illuminant colour changes with surface orientation, which no
per-neighbourhood ratio model removes, so the colour part is less reliable than the grey
gradients. Hence: a floor before the logarithm set from the measured noise
(:mod:`vision.features.colour_input`), clipped pixels neutralised, each m-image block weighted
by its contrast over the image's noise (:func:`block_contrast`), and the grey descriptor kept
as the first block so the colour part adds to it instead of replacing it.
"""

from __future__ import annotations

import cv2
import numpy as np

from vision.features.colour_input import (
    check_white_level,
    clipped_weight,
    linear_from_image,
    m_images_uint8,
    srgb_decode,
)
from vision.features.colour_input import noise_floor as _noise_floor
from vision.features.opencv import keypoints_from_cv
from vision.features.types import Keypoints

__all__ = [
    "NOISE_FLOOR",
    "SATURATION",
    "block_contrast",
    "joint_m_images",
    "joint_raw",
    "robust_m_images",
]

#: Floor before the logarithms, in units of the measured noise sigma (3 sigma: a pixel whose
#: value is within the noise of black gets a log ratio near 0).
NOISE_FLOOR = 3.0
#: Relative level at which a channel counts as clipped (its ratios are then neutralised).
SATURATION = 0.98
_JOINT_M = (0, 2)  # M1 = log(R/G) and M3 = log(G/B); M2 = M1 + M3


def _m_images_uint8(m: np.ndarray) -> np.ndarray:

    return m_images_uint8(m)


def robust_m_images(
    lin: np.ndarray,
    *,
    floor: float,
    weight: np.ndarray | None = None,
    pairs: tuple[int, ...] | None = None,
) -> np.ndarray:
    """Noise-aware m-images: equations 15-17 on ``log(C + floor)`` of linear values.

    Parameters
    ----------
    lin : ndarray of shape (H, W, 3), float32
        Relative linear light (:func:`vision.features.colour_input.linear_from_image`).
    floor : float
        Added before the logarithm (> 0, relative units; :func:`~vision.features.colour_input.
        noise_floor`): a pixel within a few noise levels of black gets log ratios near 0.
    weight : ndarray of shape (H, W), optional
        Per-pixel reliability in [0, 1] (0 at clipped pixels); the log ratios are multiplied by
        it, so unreliable pixels read as neutral (ratio 1).
    pairs : tuple of int, optional
        Which of M1, M2, M3 (0, 1, 2) to return; default all three.

    Returns
    -------
    ndarray of shape (len(pairs), H, W), float32
        ``M1 = log(R/G)``, ``M2 = log(R/B)``, ``M3 = log(G/B)`` minus their medians over the
        reliable pixels, times ``weight``.
    """
    if not floor > 0:
        raise ValueError(f"floor must be > 0, got {floor!r}")
    lg = np.log(lin + np.float32(floor))
    r, g, b = lg[..., 0], lg[..., 1], lg[..., 2]
    m = np.stack(
        [r - g, r - b, g - b] if pairs is None else [(r - g, r - b, g - b)[i] for i in pairs]
    )
    # Medians over a 1-in-16 grid of the reliable pixels (the centring needs no more).
    sub = m[:, ::4, ::4].reshape(len(m), -1)
    if weight is not None:
        sub = sub[:, weight[::4, ::4].reshape(-1) > 0.5]
    med = np.median(sub, axis=1) if sub.size else np.zeros(len(m), np.float32)
    m -= med.astype(np.float32)[:, None, None]
    if weight is not None:
        m *= weight[None]
    return m.astype(np.float32)


def block_contrast(m: np.ndarray, kp: Keypoints) -> np.ndarray:
    """Colour contrast of each m-image around each keypoint relative to the image's noise.

    ``c = g / (g + g_noise)`` in [0, 1): ``g`` is the mean gradient magnitude of the m-image
    in the keypoint's window (a square of half-width ``3 size_px``, about the extent of SIFT's
    Gaussian-weighted descriptor window, via an integral image), ``g_noise`` the median
    gradient magnitude over the image (most pixels hold no colour edge, so the median measures
    the log-ratio noise). The descriptor blocks of an m-image are normalised to unit length by
    SIFT and SURF; multiplying them by ``c`` keeps a block of pure noise from weighing as much
    as a block of real colour edges (issue 17).

    Returns
    -------
    ndarray of shape (N, 3), float32
    """
    n, (h, w) = len(kp), m.shape[1:]
    out = np.zeros((n, len(m)), np.float32)
    if n == 0:
        return out
    r = np.clip(np.rint(3.0 * kp.size_px), 2, max(2, min(h, w) // 2)).astype(np.int64)
    x = np.clip(np.rint(kp.xy[:, 0]).astype(np.int64), 0, w - 1)
    y = np.clip(np.rint(kp.xy[:, 1]).astype(np.int64), 0, h - 1)
    x0, x1 = np.clip(x - r, 0, w), np.clip(x + r + 1, 0, w)
    y0, y1 = np.clip(y - r, 0, h), np.clip(y + r + 1, 0, h)
    area = ((x1 - x0) * (y1 - y0)).astype(np.float64)
    for k, mk in enumerate(m):
        gx = cv2.Sobel(mk, cv2.CV_32F, 1, 0, ksize=3) / 8.0
        gy = cv2.Sobel(mk, cv2.CV_32F, 0, 1, ksize=3) / 8.0
        mag = np.sqrt(gx * gx + gy * gy)
        g_noise = max(float(np.median(mag[::4, ::4])), 1e-4)
        ii = cv2.integral(mag, sdepth=cv2.CV_64F)
        s = ii[y1, x1] - ii[y0, x1] - ii[y1, x0] + ii[y0, x0]
        g = s / np.maximum(area, 1.0)
        out[:, k] = g / (g + g_noise)
    return out


def _octave_at_least_zero(kps: list[cv2.KeyPoint]) -> list[cv2.KeyPoint]:
    """Copies of OpenCV SIFT keypoints whose packed octave -1 (the doubled image) is moved to
    octave 0, same layer: the m-image descriptors are then computed without OpenCV's 2x
    upsampled pyramid level, four times less area, and on a slightly smoother image (colour
    is a low-frequency signal; the window size still follows ``size``)."""
    out = []
    for k in kps:
        o = k.octave & 0xFF
        if o >= 128:  # negative octave: keep layer and sub-layer offset, octave 0
            packed = (k.octave & ~0xFF) & 0xFFFFFFFF
            packed = packed - (1 << 32) if packed >= 1 << 31 else packed
            k = cv2.KeyPoint(k.pt[0], k.pt[1], k.size, k.angle, k.response, packed, k.class_id)
        out.append(k)
    return out


def _sift_detect_describe(
    grey: np.ndarray,
    *,
    max_features: int | None = None,
    threshold: float | None = None,
    mask: np.ndarray | None = None,
) -> tuple[Keypoints, list[cv2.KeyPoint], np.ndarray]:
    """OpenCV SIFT keypoints and grey descriptors exactly as ``extract(grey, "sift")`` finds
    them (same detector call and trimming), with OpenCV's keypoints for ``compute``."""
    if threshold is not None and not threshold > 0:
        raise ValueError(f"threshold must be > 0, got {threshold!r}")
    if max_features is not None and max_features < 1:
        raise ValueError(f"max_features must be >= 1, got {max_features!r}")
    kw = {} if threshold is None else {"contrastThreshold": float(threshold)}
    det = cv2.SIFT_create(nfeatures=max_features or 0, **kw)  # type: ignore[attr-defined]  # missing from the OpenCV stubs
    m = None if mask is None else (np.asarray(mask) > 0).astype(np.uint8)
    kps, desc = det.detectAndCompute(grey, m)
    kps = list(kps)
    if desc is None or not kps:
        return Keypoints.empty(), [], np.zeros((0, 128), np.float32)
    if max_features and len(kps) > max_features:
        order = np.argsort([-k.response for k in kps])[:max_features]
        kps = [kps[i] for i in order]
        desc = desc[order]
    return keypoints_from_cv(kps), kps, desc.astype(np.float32)


def _m_descriptors_sift(m: np.ndarray, kps: list[cv2.KeyPoint]) -> np.ndarray:
    sift = cv2.SIFT_create()  # type: ignore[attr-defined]  # missing from the OpenCV stubs
    kk = _octave_at_least_zero(kps)
    parts = []
    for mu8 in _m_images_uint8(m):
        got, d = sift.compute(mu8, kk)
        if d is None or len(got) != len(kk):
            raise RuntimeError("OpenCV SIFT dropped keypoints while describing an m-image")
        parts.append(d.astype(np.float32))
    return np.stack(parts, axis=1)  # (N, n_m, 128)


def joint_m_images(
    rgb: np.ndarray,
    *,
    transfer: str = "linear",
    white_level: float | None = None,
    noise_floor: float = NOISE_FLOOR,
    saturation: float = SATURATION,
    pairs: tuple[int, ...] | None = None,
) -> np.ndarray:
    """The noise-aware m-images of an RGB camera image (:func:`robust_m_images` with the floor
    ``noise_floor`` times the measured noise and the clipped pixels neutralised).

    Returns
    -------
    ndarray of shape (len(pairs), H, W), float32
    """
    w = check_white_level(rgb, white_level)
    lin = linear_from_image(rgb, transfer=transfer, white_level=w)
    step = 1.0 / w
    if transfer == "srgb":  # one DN near black of the decoded curve
        step = float(srgb_decode(np.float32(1.0 / w)))
    floor = max(_noise_floor(lin, step, noise_floor), 1e-6)
    weight = clipped_weight(lin, saturation) if saturation < 1.0 else None
    return robust_m_images(lin, floor=floor, weight=weight, pairs=pairs)


def joint_raw(
    rgb: np.ndarray, grey: np.ndarray, base: str, detect: dict, opts: dict, colour: dict
) -> tuple:
    """Keypoints and the joint raw descriptor of one image.

    The grey base descriptor (OpenCV SIFT, 128, or VisionCell's SURF, 64) followed by the base
    descriptors of M1 and M3 (M2 = M1 + M3 adds little; its slot goes to the grey block, so
    the raw length stays 3 x the base's), each multiplied by ``colour_weight`` times its
    :func:`block_contrast`.

    Parameters
    ----------
    rgb : ndarray (H, W, 3), uint8 or uint16
    grey : ndarray (H, W), uint8
        Detection image (:func:`vision.features.colour.detection_grey`).
    base : {"sift", "surf"}
    detect : dict
        ``max_features``, ``threshold``, ``mask``.
    opts : dict
        SURF options (``upright``, ``extended``, ``n_octaves``).
    colour : dict
        ``transfer``, ``white_level``, ``noise_floor``, ``saturation``, ``colour_weight``.

    Returns
    -------
    (Keypoints, ndarray of shape (N, 384) or (N, 192), float32)
    """
    colour = dict(colour)
    beta = colour.pop("colour_weight")
    m = joint_m_images(rgb, **colour, pairs=_JOINT_M)
    if base == "sift":
        kp, cvk, g = _sift_detect_describe(grey, **detect)
        if len(kp) == 0:
            return kp, np.zeros((0, 384), np.float32)
        parts = _m_descriptors_sift(m, cvk)
    else:
        from vision.features.surf import surf_describe, surf_keypoints

        det = {k: v for k, v in detect.items() if v is not None}
        kp = surf_keypoints(grey, **det, **opts)
        width = 128 if opts.get("extended") else 64
        if len(kp) == 0:
            return kp, np.zeros((0, 3 * width), np.float32)
        up = bool(opts.get("upright", False))
        ext = bool(opts.get("extended", False))
        g = np.asarray(surf_describe(grey, kp, upright=up, extended=ext), np.float32)
        parts = np.stack(
            [np.asarray(surf_describe(mk, kp, upright=up, extended=ext), np.float32) for mk in m],
            axis=1,
        )
    c = block_contrast(m, kp)
    parts = parts * (np.float32(beta) * c)[:, :, None]
    return kp, np.concatenate([g, parts.reshape(len(kp), -1)], axis=1).astype(np.float32)
