"""The joint layout of the colour descriptor: the grey base descriptor followed by
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
by the Wiener gain of its gradient energy over what the sensor's shot and read noise
(measured in the image) would give (:func:`block_snr_weight`; 0 where colour holds only
noise), and the grey descriptor kept as the first block so the colour part adds to it
instead of replacing it.
"""

from __future__ import annotations

import cv2
import numpy as np

from vision.features.colour_input import (
    M_SCALE,
    check_white_level,
    clipped_weight,
    linear_from_image,
    m_images_uint8,
    noise_estimates,
    srgb_decode,
)
from vision.features.colour_input import noise_floor as _noise_floor
from vision.features.opencv import keypoints_from_cv
from vision.features.types import Keypoints

__all__ = [
    "NOISE_FLOOR",
    "SATURATION",
    "block_snr_weight",
    "joint_m_images",
    "joint_raw",
    "m_noise_variance",
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


#: Mean squared magnitude of the ``Sobel / 8`` gradient of unit-variance white noise:
#: each component sums the squared kernel taps, ``(1 + 4 + 1) * 2 / 64``, and there are two.
_SOBEL_NOISE_GAIN = 2.0 * 12.0 / 64.0
_PAIR_CHANNELS = ((0, 1), (0, 2), (1, 2))  # M1 = log(R/G), M2 = log(R/B), M3 = log(G/B)


def m_noise_variance(
    lin: np.ndarray,
    *,
    floor: float,
    shot: float,
    read: float,
    weight: np.ndarray | None = None,
    pairs: tuple[int, ...] | None = None,
) -> np.ndarray:
    """Expected noise variance of each m-image pixel, propagated from the sensor noise.

    With ``var(C) = shot C + read`` (:func:`vision.features.colour_input.noise_model`) and
    ``M = log(C1 + f) - log(C2 + f)``, first-order propagation gives
    ``var(M) = var(C1) / (C1 + f)^2 + var(C2) / (C2 + f)^2`` (the two channels' noise is
    independent); pixels whose log ratios are multiplied by a clipping weight ``w`` get
    ``w^2`` times that.

    Returns
    -------
    ndarray of shape (len(pairs), H, W), float32
    """
    return _m_variances(lin, floor, shot, (read,), weight, pairs)[0]


def _m_variances(
    lin: np.ndarray,
    floor: float,
    shot: float,
    reads: tuple[float, ...],
    weight: np.ndarray | None,
    pairs: tuple[int, ...] | None,
) -> list[np.ndarray]:
    """:func:`m_noise_variance` for several read-noise levels, the first with ``shot`` and
    the others without (the quantisation's share), sharing ``1 / (C + f)^2``."""
    idx = range(3) if pairs is None else pairs
    x = lin + np.float32(floor)
    inv = 1.0 / (x * x)
    w2 = None if weight is None else (weight * weight)[None]
    outs = []
    for j, read in enumerate(reads):
        num = np.float32(shot) * lin + np.float32(read) if j == 0 else np.float32(read)
        rel = num * inv  # var(log(C + f)) per channel
        out = np.stack(
            [rel[..., _PAIR_CHANNELS[i][0]] + rel[..., _PAIR_CHANNELS[i][1]] for i in idx]
        )
        if w2 is not None:
            out *= w2
        outs.append(out.astype(np.float32))
    return outs


def block_snr_weight(
    m: np.ndarray,
    var: np.ndarray,
    kp: Keypoints,
    *,
    extra_var: float = 0.0,
    radius_per_size: float = 3.0,
    quant_var: np.ndarray | None = None,
) -> np.ndarray:
    """Weight of each m-image block of each keypoint by its signal over the expected noise.

    In the keypoint's window (a square of half-width ``radius_per_size * size_px``, the extent
    of the descriptor's window: 3 for OpenCV SIFT, whose Gaussian window has sigma ``3 size``
    / 2 ... ``3 size``; 0.5 for VisionCell's SURF, whose ``size_px`` is the side of its 20 s
    window; via integral images) ``E`` is the mean squared gradient of
    the m-image and ``N`` what the sensor noise alone would give, ``N = 0.375 mean(var(M) +
    extra_var)`` (the ``Sobel / 8`` gradient of white noise; :func:`m_noise_variance`). The
    weight is the Wiener gain ``max(0, E - N) / E`` (the share of the gradient energy that is
    signal): 0 where the colour ratios hold nothing but noise -- dark, flat or clipped windows
    -- so the joint descriptor is then exactly the grey one, towards 1 at strong colour edges.
    ``quant_var`` (the quantisation's share of ``var``, same shape): the model takes it as
    independent per-pixel noise, which it is only where the sensor noise dithers it; given,
    the window's white noise is the mean squared finest diagonal detail ``HH`` of the m-image
    clipped to [``var - quant_var``, ``var``] (flat dark patches of 8-bit linear
    images). The rest of the quantisation, ``Q = var - white``, is not dropped: it is coherent
    -- rounding without dither errs by the same amount over a flat region, an error of the
    region's level of variance ``step^2 / 12`` per channel all the same (Widrow, Kollar and
    Liu, IEEE Trans. Instrum. Meas. 45(2), 1996: the white, uniform model of the rounding
    error holds only when the signal spans several steps between samples) -- so it moves the
    region's edges as the signal does and no filter scale averages it out. For
    piecewise-constant fields on one partition the squared steps scale with the variance of
    the levels, so its share of the window's gradient energy is ``Q / V`` with ``V`` the
    m-image's variance over the window; the weight is then ``max(0, 1 - N / E - Q / V)``
    (the dim red channel of the SFU chart, 0-10 DN, whose rounded log ratios
    changed the M1 descriptor between the lamps though its weight was 0.9).

    Returns
    -------
    ndarray of shape (N, len(m)), float32, in [0, 1)
    """
    n, (h, w) = len(kp), m.shape[1:]
    out = np.zeros((n, len(m)), np.float32)
    if n == 0:
        return out
    r = np.clip(np.rint(radius_per_size * kp.size_px), 2, max(2, min(h, w) // 2))
    r = r.astype(np.int64)
    x = np.clip(np.rint(kp.xy[:, 0]).astype(np.int64), 0, w - 1)
    y = np.clip(np.rint(kp.xy[:, 1]).astype(np.int64), 0, h - 1)
    x0, x1 = np.clip(x - r, 0, w), np.clip(x + r + 1, 0, w)
    y0, y1 = np.clip(y - r, 0, h), np.clip(y + r + 1, 0, h)
    area = np.maximum(((x1 - x0) * (y1 - y0)).astype(np.float64), 1.0)

    def window_mean(img: np.ndarray) -> np.ndarray:
        ii = cv2.integral(img, sdepth=cv2.CV_64F)
        return (ii[y1, x1] - ii[y0, x1] - ii[y1, x0] + ii[y0, x0]) / area

    for k, mk in enumerate(m):
        coherent = np.zeros(n)
        gx = cv2.Sobel(mk, cv2.CV_32F, 1, 0, ksize=3)
        gy = cv2.Sobel(mk, cv2.CV_32F, 0, 1, ksize=3)
        energy = window_mean((gx * gx + gy * gy) * np.float32(1.0 / 64.0))
        model = window_mean(var[k])
        if quant_var is not None:
            # The model counts quantisation as independent noise per pixel; with less sensor
            # noise than one step it is not (a flat patch rounds alike at every pixel). Its
            # share is bounded by what the m-image's finest diagonal detail holds (texture
            # only adds to that): noise = detail clipped to [sensor part, model].
            hh = 0.5 * (mk[:-1, :-1] - mk[:-1, 1:] - mk[1:, :-1] + mk[1:, 1:])
            detail = np.zeros_like(mk)
            detail[:-1, :-1] = hh * hh
            sensor = model - window_mean(quant_var[k])
            white = np.clip(window_mean(detail), sensor, model)
            # The rest of the quantisation is coherent: an error of each flat region's level
            # (uniform, variance ``model - white`` on average), constant inside the region
            # like the signal, so it changes the region's steps as the signal makes them and
            # does not average out over the descriptor's boxes. For piecewise-constant
            # fields on one partition the squared steps scale with the variance of the
            # levels, so that error's share of the gradient energy is its variance over the
            # window's variance of the m-image.
            mean = window_mean(mk)
            spread = np.maximum(window_mean(mk * mk) - mean * mean, 1e-30)
            coherent = np.minimum((model - white) / spread, 1.0)
            model = white
        noise = _SOBEL_NOISE_GAIN * (model + extra_var)
        gain = 1.0 - noise / np.maximum(energy, 1e-30) - coherent
        out[:, k] = np.where(gain > 0.0, gain, 0.0)
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


def _half_resolution(kps: list[cv2.KeyPoint]) -> list[cv2.KeyPoint]:
    """OpenCV SIFT keypoints (octave >= 0) for an image of half the size (2x2 pixel means):
    position ``(x - 0.5) / 2``, half the size, one octave lower but at least 0, same layer.
    Keypoints of octave >= 1 get the same pyramid level as at full size; those of octave 0 a
    level one octave smoother (the colour ratios are smooth; the window follows ``size``)."""
    out = []
    for k in kps:
        o = k.octave & 0xFF  # >= 0 here (:func:`_octave_at_least_zero`)
        packed = (k.octave & ~0xFF) | max(o - 1, 0)
        packed = packed - (1 << 32) if packed >= 1 << 31 else packed
        pt = ((k.pt[0] - 0.5) / 2.0, (k.pt[1] - 0.5) / 2.0)
        out.append(cv2.KeyPoint(pt[0], pt[1], k.size / 2.0, k.angle, k.response, packed))
    return out


def _m_descriptors_sift(m: np.ndarray, kps: list[cv2.KeyPoint]) -> np.ndarray:
    """OpenCV SIFT descriptors of the m-images at ``kps``, computed on the m-images at half
    resolution (:func:`_half_resolution`): a quarter of the pyramid's area."""
    sift = cv2.SIFT_create()  # type: ignore[attr-defined]  # missing from the OpenCV stubs
    kk = _half_resolution(_octave_at_least_zero(kps))
    h, w = m.shape[1] // 2, m.shape[2] // 2
    parts = []
    for mk in m:
        half = cv2.resize(mk, (w, h), interpolation=cv2.INTER_AREA)
        got, d = sift.compute(_m_images_uint8(half[None])[0], kk)
        if d is None or len(got) != len(kk):
            raise RuntimeError("OpenCV SIFT dropped keypoints while describing an m-image")
        parts.append(d.astype(np.float32))
    return np.stack(parts, axis=1)  # (N, n_m, 128)


def _m_images_and_noise(
    rgb: np.ndarray,
    *,
    transfer: str,
    white_level: float | None,
    noise_floor: float,
    saturation: float,
    pairs: tuple[int, ...] | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The noise-aware m-images, their expected noise variance (:func:`m_noise_variance`
    with the sensor noise measured in the image, :func:`~vision.features.colour_input.
    noise_model`) and the quantisation's share of it."""
    w = check_white_level(rgb, white_level)
    lin = linear_from_image(rgb, transfer=transfer, white_level=w)
    step = 1.0 / w
    if transfer == "srgb":  # one DN near black of the decoded curve
        step = float(srgb_decode(np.float32(1.0 / w)))
    floor, shot, read = noise_estimates(lin, step, noise_floor)
    floor = max(floor, 1e-6)
    weight = clipped_weight(lin, saturation) if saturation < 1.0 else None
    m = robust_m_images(lin, floor=floor, weight=weight, pairs=pairs)
    q = step * step / 12.0  # the quantisation's share of ``read``
    var, quant = _m_variances(lin, floor, shot, (read, q), weight, pairs)
    return m, var, quant


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


def joint_parts(
    rgb: np.ndarray, grey: np.ndarray, base: str, detect: dict, opts: dict, colour: dict
) -> tuple[Keypoints, np.ndarray, np.ndarray, np.ndarray]:
    """Keypoints, grey base descriptors (N, D), unweighted m-image descriptors (N, 2, D) of
    M1 and M3, and their noise weights (N, 2) (:func:`block_snr_weight`) of one image.

    ``colour`` holds ``transfer``, ``white_level``, ``noise_floor``, ``saturation``.
    """
    m, var, quant = _m_images_and_noise(rgb, **colour, pairs=_JOINT_M)
    if base == "sift":
        kp, cvk, g = _sift_detect_describe(grey, **detect)
        width = 128
        # The uint8 mapping for OpenCV adds its quantisation step to the m-image noise.
        c = block_snr_weight(m, var, kp, extra_var=(1.0 / M_SCALE) ** 2 / 12.0, quant_var=quant)
        parts = np.zeros((len(kp), len(m), width), np.float32)
        for k, mk in enumerate(m):
            live = np.flatnonzero(c[:, k] > 0)  # blocks of weight 0 stay 0: not described
            if len(live):
                parts[live, k] = _m_descriptors_sift(mk[None], [cvk[i] for i in live])[:, 0]
        return kp, g, parts, c
    from vision.features.surf import surf_describe_channels, surf_features

    det = {key: v for key, v in detect.items() if v is not None}
    # The grey base exactly as extract(grey, "surf"): detection, orientation and descriptors
    # on one integral image.
    fg = surf_features(grey, **det, **opts)
    kp = fg.keypoints
    up = bool(opts.get("upright", False))
    ext = bool(opts.get("extended", False))
    width = 128 if ext else 64
    if len(kp) == 0:
        e = np.zeros((0, width), np.float32)
        return kp, e, np.zeros((0, 2, width), np.float32), np.zeros((0, 2), np.float32)
    g = np.asarray(fg.descriptors, np.float32)
    c = block_snr_weight(m, var, kp, radius_per_size=0.5, quant_var=quant)
    # Both m-images in one pass, at the grey keypoints' positions, scales and orientations;
    # blocks of weight 0 are not computed (they stay 0).
    parts = surf_describe_channels(m, kp, live=c > 0, upright=up, extended=ext, coarse=True)
    return kp, g, parts, c


def joint_raw(
    rgb: np.ndarray, grey: np.ndarray, base: str, detect: dict, opts: dict, colour: dict
) -> tuple:
    """Keypoints and the joint raw descriptor of one image.

    The grey base descriptor (OpenCV SIFT, 128, or VisionCell's SURF, 64) followed by the base
    descriptors of M1 and M3 (M2 = M1 + M3 adds little; its slot goes to the grey block, so
    the raw length stays 3 x the base's), each multiplied by ``colour_weight`` times its
    noise weight (:func:`block_snr_weight`): where the colour ratios carry no signal above
    the sensor noise the colour blocks are 0 and the descriptor is the grey one.

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
    kp, g, parts, c = joint_parts(rgb, grey, base, detect, opts, colour)
    parts = parts * (np.float32(beta) * c)[:, :, None]
    flat = parts.reshape(len(kp), parts.shape[1] * parts.shape[2])
    return kp, np.concatenate([g, flat], axis=1).astype(np.float32)
