"""Camera values for the colour-ratio descriptor: linearisation, noise floor, clipping.

The invariance of the m1 m2 m3 ratios (chapter equations 15-17) to the illuminant holds for
*linear* sensor values: a diagonal change of the light multiplies R, G, B by constants, which
the log ratios subtract away. Real cameras add what that model leaves out:

* a transfer function: 8-bit sRGB output is ``V = f(L)`` with the sRGB curve (IEC 61966-2-1),
  so a gain on ``L`` is no gain on ``V``. ``transfer="srgb"`` inverts the curve first;
* noise: shot and read noise of a dark pixel make ``log(R/G)`` swing widely. We add a floor
  ``f`` before the logarithm, ``log(C + f)``, set from the noise measured in the image itself
  (:func:`noise_sigma`, Donoho's median absolute deviation of the finest diagonal detail,
  Biometrika 81(3), 1994), so that ratios of pixels within a few noise levels of black shrink
  towards 1 (log 0) instead of swinging;
* clipping: where a channel saturates the ratio is wrong; such pixels (and a 1-pixel border
  around them) get weight 0 and their log ratios are set to the neutral 0.

Everything here works on relative values ``L / white_level`` in [0, 1], so 8-bit and 16-bit
inputs are treated alike.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import ArrayLike

__all__ = [
    "TRANSFERS",
    "check_white_level",
    "clipped_weight",
    "linear_from_image",
    "noise_estimates",
    "noise_floor",
    "noise_model",
    "noise_sigma",
    "srgb8_from_linear",
    "srgb_decode",
    "srgb_encode",
]

#: Transfer functions ``extract(..., transfer=...)`` knows: the values are linear already, or
#: sRGB-encoded (IEC 61966-2-1) and linearised before the ratios.
TRANSFERS = ("linear", "srgb")
_MAX_WHITE = 65535.0


def srgb_decode(v: ArrayLike) -> np.ndarray:
    """sRGB-encoded values in [0, 1] to linear light in [0, 1] (IEC 61966-2-1)."""
    v = np.asarray(v, dtype=np.float32)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4).astype(np.float32)


def srgb_encode(x: np.ndarray) -> np.ndarray:
    """Linear light in [0, 1] (clipped) to sRGB-encoded values in [0, 1]."""
    x = np.clip(np.asarray(x, dtype=np.float32), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055).astype(np.float32)


def check_white_level(image: np.ndarray, white_level: float | None) -> float:
    """The white level of ``image`` (its dtype's maximum unless given), validated."""
    if white_level is None:
        return 255.0 if image.dtype == np.uint8 else _MAX_WHITE
    if isinstance(white_level, bool) or not isinstance(white_level, int | float | np.number):
        raise ValueError(f"white_level must be a number, got {white_level!r}")
    top = 255.0 if image.dtype == np.uint8 else _MAX_WHITE
    if not (np.isfinite(white_level) and 1.0 <= white_level <= top):
        raise ValueError(
            f"white_level must be in [1, {top:g}] for {image.dtype}, got {white_level!r}"
        )
    return float(white_level)


def srgb8_from_linear(rgb: np.ndarray, *, white_level: float | None = None) -> np.ndarray:
    """8-bit sRGB encoding of linear camera values (what a camera's 8-bit output shows).

    Parameters
    ----------
    rgb : ndarray of shape (H, W, 3) or (H, W), uint8 or uint16
        Linear values; ``white_level`` (default the dtype's maximum) maps to 255.

    Returns
    -------
    ndarray of the same shape, uint8
    """
    rgb = np.asarray(rgb)
    if rgb.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"rgb must be uint8 or uint16, got {rgb.dtype}")
    w = check_white_level(rgb, white_level)
    return np.rint(255.0 * srgb_encode(rgb.astype(np.float32) / np.float32(w))).astype(np.uint8)


def linear_from_image(
    rgb: np.ndarray, *, transfer: str = "linear", white_level: float | None = None
) -> np.ndarray:
    """Relative linear light ``L / white`` in [0, 1] of an RGB image, float32 (H, W, 3).

    ``transfer="srgb"`` inverts the sRGB curve (for cameras that apply it); ``"linear"``
    only divides by the white level.
    """
    if transfer not in TRANSFERS:
        raise ValueError(f"transfer must be one of {', '.join(TRANSFERS)}, got {transfer!r}")
    w = check_white_level(rgb, white_level)
    x = np.minimum(rgb.astype(np.float32) / np.float32(w), 1.0)
    return srgb_decode(x) if transfer == "srgb" else x


def noise_sigma(x: np.ndarray) -> float:
    """Robust estimate of the noise standard deviation of an image (any units).

    Donoho and Johnstone's estimator: ``median(|HH|) / 0.6745`` of the finest diagonal Haar
    detail ``HH = (a - b - c + d) / 2`` of 2x2 blocks, which texture barely reaches, averaged
    over the channels. Quantisation counts as noise (``x`` of 8-bit data never gives less than
    the step / sqrt(12) floor that :func:`noise_floor` adds).
    """
    x = np.asarray(x, dtype=np.float32)
    if x.ndim == 2:
        x = x[..., None]
    if x.shape[0] >= 4 and x.shape[1] >= 4:  # a 1-in-4 subsample of the blocks suffices
        return float(np.median(_fine_detail(x)[0]) / 0.6745)
    h, w = (x.shape[0] // 2) * 2, (x.shape[1] // 2) * 2
    a, b = x[0:h:2, 0:w:2], x[0:h:2, 1:w:2]
    c, d = x[1:h:2, 0:w:2], x[1:h:2, 1:w:2]
    return float(np.median(np.abs(0.5 * (a - b - c + d))) / 0.6745)


def _fine_detail(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``|HH|``, the block mean and the block maximum of every second 2x2 block along each
    axis (a quarter of the blocks) of an (H, W, C) image with H, W >= 4, flattened over
    blocks and channels: what :func:`noise_sigma` and :func:`noise_model` both measure."""
    h, w = (x.shape[0] // 2) * 2, (x.shape[1] // 2) * 2
    p, r = x[0:h:4, 0:w:4], x[0:h:4, 1:w:4]
    s, t = x[1:h:4, 0:w:4], x[1:h:4, 1:w:4]
    hh = np.abs(0.5 * (p - r - s + t)).reshape(-1)
    mu = (0.25 * (p + r + s + t)).reshape(-1)
    return hh, mu, np.maximum.reduce([p, r, s, t]).reshape(-1)


def noise_floor(lin: np.ndarray, step: float, k: float) -> float:
    """The floor ``f = k * sigma`` added before the logarithms (relative units).

    ``sigma`` combines the measured noise (:func:`noise_sigma`) and the quantisation of the
    input (``step / sqrt(12)``, ``step`` = one digital number relative to white) in quadrature.
    """
    s = noise_sigma(lin)
    q = step / np.sqrt(12.0)
    return float(k * np.hypot(s, q))


def clipped_weight(lin: np.ndarray, saturation: float) -> np.ndarray:
    """Weight (H, W) float32: 0 where any channel reaches ``saturation`` (relative) or
    touches such a pixel (3x3 dilation), 1 elsewhere."""
    sat: np.ndarray = np.asarray((lin >= np.float32(saturation)).any(axis=2), dtype=np.uint8)
    if sat.any():
        sat = cv2.dilate(sat, np.ones((3, 3), np.uint8))
    return (1.0 - sat).astype(np.float32)


#: Fixed mapping of an m-image to uint8 for OpenCV's SIFT: ``128 + M_SCALE * M``, clipped.
#: It covers log ratios in [-3.2, +3.2] (colour ratios up to 24:1 around the image's median)
#: with a step of 1/40 = 0.025 (2.5 % in the ratio); stronger ratios saturate.
M_SCALE = 40.0


def m_images_uint8(m: np.ndarray) -> np.ndarray:
    """Map m-images to uint8 by the fixed ``128 + 40 M`` (:data:`M_SCALE`), rounded and
    clipped, for OpenCV's SIFT, which reads only 8-bit images."""
    return np.clip(np.rint(128.0 + M_SCALE * np.asarray(m)), 0, 255).astype(np.uint8)


def noise_model(lin: np.ndarray, step: float, *, bins: int = 16) -> tuple[float, float]:
    """Signal-dependent sensor noise ``var(C) = a C + b`` measured in the image itself.

    The Poisson-Gaussian model of a raw sensor (shot noise ``a C``, read noise and quantisation
    ``b``; Foi, Trimeche, Katkovnik and Egiazarian, "Practical Poissonian-Gaussian noise
    modeling and fitting for single-image raw-data", IEEE TIP 17(10), 2008): the finest
    diagonal Haar detail ``HH = (p - q - r + s) / 2`` of 2x2 blocks, which texture barely
    reaches, has the variance of one pixel's noise; its robust variance
    ``(median |HH| / 0.6745)^2`` is taken in ``bins`` quantile bins of the block mean (all
    channels pooled, clipped blocks left out) and ``a, b >= 0`` are fitted by least squares.
    The quantisation of the input (``step^2 / 12``, ``step`` = one digital number relative to
    white) is added to ``b``.

    Parameters
    ----------
    lin : ndarray of shape (H, W, 3), float32
        Relative linear light in [0, 1].
    step : float
        One digital number relative to white (> 0).

    Returns
    -------
    (a, b) : tuple of float
        Shot-noise gain and the variance at black, in relative units.
    """
    x = np.asarray(lin, dtype=np.float32)
    if x.ndim == 2:
        x = x[..., None]
    q = step * step / 12.0
    if x.shape[0] < 4 or x.shape[1] < 4:
        return 0.0, float(q)
    # Every second 2x2 block along each axis (a quarter of them) is plenty for 16 bins.
    return _fit_noise(*_fine_detail(x), q, bins)


def noise_estimates(lin: np.ndarray, step: float, k: float) -> tuple[float, float, float]:
    """``(noise_floor(lin, step, k), *noise_model(lin, step))`` from one pass over the image's
    fine Haar detail (both measure the same blocks)."""
    x = np.asarray(lin, dtype=np.float32)
    if x.ndim == 2:
        x = x[..., None]
    if x.shape[0] < 4 or x.shape[1] < 4:
        return (noise_floor(x, step, k), *noise_model(x, step))
    hh, mu, peak = _fine_detail(x)
    sigma = float(np.median(hh) / 0.6745)
    floor = float(k * np.hypot(sigma, step / np.sqrt(12.0)))
    return (floor, *_fit_noise(hh, mu, peak, step * step / 12.0, 16))


def _fit_noise(
    hh: np.ndarray, mu: np.ndarray, peak: np.ndarray, q: float, bins: int
) -> tuple[float, float]:
    """The least-squares fit of :func:`noise_model` from its blocks' ``|HH|``, means and
    maxima (clipped blocks, maximum >= 0.98, left out); ``q`` the quantisation variance."""
    keep = peak < 0.98
    hh, mu = hh[keep], mu[keep]
    if hh.size < 4 * bins:
        return 0.0, float(np.median(hh) / 0.6745) ** 2 + q if hh.size else q
    order = np.argsort(mu, kind="stable")
    cm, cv = [], []
    for sel in np.array_split(order, bins):  # quantile bins of the block mean
        cm.append(float(mu[sel].mean()))
        cv.append(float(np.median(hh[sel]) / 0.6745) ** 2)
    m_, v_ = np.asarray(cm), np.asarray(cv)
    a_mat = np.stack([m_, np.ones_like(m_)], axis=1)
    a, b = np.linalg.lstsq(a_mat, v_, rcond=None)[0]
    if a < 0:  # no measurable shot noise: constant variance
        a, b = 0.0, float(np.median(v_))
    elif b < 0:  # no measurable read noise: through the origin
        a, b = float(np.dot(m_, v_) / max(np.dot(m_, m_), 1e-30)), 0.0
    return float(a), float(b) + q
