"""Colour signatures of an object region, to tell apart models that look alike in grey.

The local features are grey (SIFT), so two models that differ only by the colour of a part
(``wheel-5spoke`` and ``wheel-5spoke-redband``: the same rim and tyre, a red band on the
tread) score alike from every viewpoint and the decision stays ``ambiguous``. The signature
below describes the colours inside the object region with the chapter's colour ratios
(section 3.4, equations 15-17; van de Weijer and Schmid, "Coloring local feature
extraction", ECCV 2006), and :func:`colour_distance` compares two of them. It is used only
to break a tie between contenders whose geometric scores are within the ambiguity margin
(:func:`vision.recognition.recognise_views`).

Signature
    Pixels are linearised (the sRGB curve, IEC 61966-2-1, inverted for a camera that
    encodes with it, ``transfer="srgb"``; values taken as they are for a linear camera,
    ``transfer="linear"``); pixels whose brightest channel is
    below :data:`DARK_LEVEL` (the ratios are noise there) or with a clipped channel (above
    :data:`CLIP_LEVEL`) are left out. Each remaining pixel gives the log ratios
    ``(log(R/G), log(B/G))`` (a floor :data:`FLOOR` is added to every channel before the
    logarithm, so a nearly black channel does not swing the ratio); the region's median
    ratios are subtracted, which is equation 17 with ``x_2`` the region's median colour: the
    difference is unchanged by the light's intensity (shading) and, under the diagonal model
    of an illuminant change, by its colour too. A pixel is *chromatic* when that difference
    is longer than :data:`CHROMA_MIN`. The signature is the share of usable pixels that are
    achromatic, then the share of chromatic ones in each of :data:`HUE_BINS` hue sectors (the
    difference's angle; each pixel's vote split between the two sectors whose centres
    enclose its hue, so that a hue on a sector boundary does not jump sectors under a small
    shift): :data:`SIGNATURE_SIZE` values summing to 1. A colour band that
    covers 2 % of the region moves 2 % of the mass out of the first value, however large the
    grey part is (a histogram of all pixels compared by overlap would hardly notice it).
    Regions with fewer than :data:`MIN_PIXELS` usable pixels have no signature (``None``).

Distance
    ``sum_h |log((p_h + e) / (q_h + e))|`` over the hue sectors ``h`` (the achromatic share
    left out) with ``e =`` :data:`CHROMA_FLOOR`: how many times more or less of each colour
    one region holds than the other, in log units, with shares below ``e`` counted as
    ``e`` so that noise-level colour does not count. It does not depend on how much grey
    surrounds the colour (a query region a little larger than the trained one halves the
    shares, a distance of log 2 per hue, where "no red at all" against 2 % red is some 2.3).
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from vision.features.colour_input import TRANSFERS, srgb_decode

__all__ = [
    "CHROMA_FLOOR",
    "CHROMA_MIN",
    "HUE_BINS",
    "SIGNATURE_SIZE",
    "check_signature",
    "colour_distance",
    "colour_signature",
    "held_sectors",
    "region_from_outline",
]

#: Hue sectors of the chromatic pixels, and the length of a log-ratio difference (from the
#: region's median colour) above which a pixel is chromatic: 0.5 is a ratio of 1.65.
HUE_BINS = 8
CHROMA_MIN = 0.5
SIGNATURE_SIZE = 1 + HUE_BINS
#: Linear levels (of 1): a pixel whose brightest channel is below ``DARK_LEVEL`` (sRGB code
#: 39) is too dark for its ratios; a channel above ``CLIP_LEVEL`` is clipped; ``FLOOR`` is
#: added to every channel before the logarithm.
DARK_LEVEL = 0.02
CLIP_LEVEL = 0.98
FLOOR = 0.004
#: Fewer usable pixels than this give no signature.
MIN_PIXELS = 200
#: Share of a hue below which it is counted as this share (noise-level colour).
CHROMA_FLOOR = 0.002


def _check_rgb(image: object) -> NDArray[np.uint8]:
    if not isinstance(image, np.ndarray) or image.dtype != np.uint8:
        raise ValueError(
            f"image must be a uint8 numpy array, got {getattr(image, 'dtype', image)!r}"
        )
    if image.ndim != 3 or image.shape[2] != 3:
        raise ValueError(f"image must be RGB of shape (H, W, 3), got {image.shape}")
    return image


def colour_signature(
    image: NDArray[np.uint8], region: ArrayLike, *, transfer: str = "srgb"
) -> NDArray[np.float32] | None:
    """The colour signature of ``region`` in ``image`` (module docstring).

    Parameters
    ----------
    image : ndarray of shape (H, W, 3), uint8
        RGB image as the camera encodes it.
    region : ndarray of shape (H, W), bool or uint8
        Non-zero inside the object region.
    transfer : {"srgb", "linear"}
        The camera's transfer curve: ``"srgb"`` values are decoded to linear first,
        ``"linear"`` ones are linear already.

    Returns
    -------
    ndarray of shape (SIGNATURE_SIZE,), float32, or None
        Normalised histogram (sum 1); ``None`` when fewer than :data:`MIN_PIXELS` pixels are
        usable.
    """
    image = _check_rgb(image)
    if transfer not in TRANSFERS:
        raise ValueError(f"transfer must be one of {', '.join(TRANSFERS)}, got {transfer!r}")
    m = np.asarray(region)
    if m.shape != image.shape[:2]:
        raise ValueError(f"region shape {m.shape} differs from the image's {image.shape[:2]}")
    sel = m > 0
    if np.count_nonzero(sel) < MIN_PIXELS:
        return None
    lin = image[sel].astype(np.float32) / 255.0  # (N, 3)
    if transfer == "srgb":
        lin = srgb_decode(lin)
    ok = (lin.max(axis=1) >= DARK_LEVEL) & (lin.max(axis=1) <= CLIP_LEVEL)
    n = int(np.count_nonzero(ok))
    if n < MIN_PIXELS:
        return None
    lg = np.log(lin[ok] + FLOOR)
    u = lg[:, 0] - lg[:, 1]  # log(R / G)
    v = lg[:, 2] - lg[:, 1]  # log(B / G)
    u = u - np.median(u)  # equation 17 against the region's median colour
    v = v - np.median(v)
    chromatic = np.hypot(u, v) > CHROMA_MIN
    # Each chromatic pixel votes for the two sectors whose centres enclose its hue, in
    # proportion to its nearness (a linearly interpolated histogram): with hard sectors a
    # colour on a sector boundary (the red band of the twin wheel, half in each of two
    # sectors) moved wholly into one sector under a small hue shift, which the comparison
    # read as a colour appearing and another vanishing.
    pos = (np.arctan2(v[chromatic], u[chromatic]) + np.pi) / (2.0 * np.pi) * HUE_BINS - 0.5
    low = np.floor(pos)
    frac = pos - low
    k0 = low.astype(np.int64) % HUE_BINS
    k1 = (k0 + 1) % HUE_BINS
    out = np.zeros(SIGNATURE_SIZE, dtype=np.float64)
    out[0] = np.count_nonzero(~chromatic)
    out[1:] = np.bincount(k0, weights=1.0 - frac, minlength=HUE_BINS) + np.bincount(
        k1, weights=frac, minlength=HUE_BINS
    )
    return (out / n).astype(np.float32)


def check_signature(signature: object) -> NDArray[np.float32]:
    """Validate a signature: finite, non-negative, of :data:`SIGNATURE_SIZE` values summing
    to 1 (within 1e-3)."""
    a = np.asarray(signature, dtype=np.float32).reshape(-1)
    if a.size != SIGNATURE_SIZE:
        raise ValueError(f"a colour signature has {SIGNATURE_SIZE} values, got {a.size}")
    if not np.all(np.isfinite(a)) or a.min() < 0.0 or abs(float(a.sum()) - 1.0) > 1e-3:
        raise ValueError("a colour signature must be finite, non-negative and sum to 1")
    return a


def colour_distance(a: ArrayLike, b: ArrayLike, *, sectors: ArrayLike | None = None) -> float:
    """Distance of two signatures (module docstring): 0 for the same colours, larger the more
    the shares of the hues differ (log units summed over the hue sectors).

    ``sectors`` (bool, :data:`HUE_BINS`) restricts the sum to those hue sectors (all when
    ``None``), e.g. to the hues that tell the compared models apart (:func:`held_sectors`).
    """
    p, q = check_signature(a), check_signature(b)
    ratio = (p[1:].astype(np.float64) + CHROMA_FLOOR) / (q[1:].astype(np.float64) + CHROMA_FLOOR)
    terms = np.abs(np.log(ratio))
    if sectors is not None:
        keep = np.asarray(sectors, dtype=bool).reshape(-1)
        if keep.size != HUE_BINS:
            raise ValueError(f"sectors must have {HUE_BINS} values, got {keep.size}")
        terms = terms[keep]
    return float(terms.sum())


def held_sectors(signatures: list[ArrayLike]) -> NDArray[np.bool_]:
    """Hue sectors that at least one of ``signatures`` holds above :data:`CHROMA_FLOOR`.

    A tie-break between models compares a query with each model's trained views; a colour
    the query shows that none of those views holds (a tint the light's colour left on a
    shaded or highlighted face that the region's median does not cancel: under a warm lamp
    beside a white ambient light, 6 % of a wheel's side view in one hue) adds the same
    distance to every model and decides nothing, but it pushed the right model past the
    distance at which it is taken to resemble its views.
    """
    if not signatures:
        return np.zeros(HUE_BINS, dtype=bool)
    shares = np.stack([check_signature(s)[1:] for s in signatures])
    return np.asarray((shares > CHROMA_FLOOR).any(axis=0), dtype=bool)


def region_from_outline(
    outline_xy: ArrayLike, shape: tuple[int, int], H: ArrayLike | None = None
) -> NDArray[np.uint8]:
    """The convex region of the points ``outline_xy`` (N, 2), mapped by the 3x3 ``H`` when
    given (``x' ~ H @ x``), as a uint8 mask of ``shape`` (H, W)."""
    pts = np.asarray(outline_xy, dtype=np.float64).reshape(-1, 2)
    if len(shape) != 2 or min(shape) < 1:
        raise ValueError(f"shape must be (H, W), got {shape!r}")
    out = np.zeros(shape, dtype=np.uint8)
    if len(pts) < 3 or not np.all(np.isfinite(pts)):
        return out
    hull = cv2.convexHull(pts.astype(np.float32)).reshape(-1, 2).astype(np.float64)
    if H is not None:
        Hm = np.asarray(H, dtype=np.float64)
        if Hm.shape != (3, 3) or not np.all(np.isfinite(Hm)):
            raise ValueError(f"H must be a finite 3x3 matrix, got shape {Hm.shape}")
        hom = np.c_[hull, np.ones(len(hull))] @ Hm.T
        if np.any(hom[:, 2] <= 1e-9):
            return out  # the outline crosses the horizon: no region
        hull = hom[:, :2] / hom[:, 2:]
    lim = 4.0 * max(shape)
    hull = np.clip(hull, -lim, lim)
    cv2.fillConvexPoly(out, np.round(hull).astype(np.int32), 1)
    return out
