"""The chapter's colour-invariant descriptor (section 3.4, equations 15-19).

The m1 m2 m3 model (van de Weijer and Schmid 2006, chapter equation 15) compares the colour
ratios of neighbouring pixels x1, x2: ``m1 = R^x1 G^x2 / (R^x2 G^x1)``. Taking logarithms
(equation 16) turns it into a difference of the per-pixel log ratio ``log(R/G)`` between
the two neighbours (equation 17). So we build three *m-images*

    M1 = log(R + eps) - log(G + eps),  M2 = log(R + eps) - log(B + eps),
    M3 = log(G + eps) - log(B + eps),

whose finite differences between neighbouring pixels -- which is all a gradient-based
descriptor (SIFT, SURF) looks at -- are exactly ``log m1``, ``log m2``, ``log m3`` for the
neighbour pairs along the image axes. A global per-channel gain (R, G, B) -> (aR, bG, cB)
adds a constant to each m-image and so leaves every neighbour difference unchanged; we also
subtract each m-image's median, which makes the m-images themselves gain-invariant. ``eps``
(:data:`EPS` = 1 digital number) keeps ``log(0)`` finite; it breaks the invariance only for
pixels within a few DN of black, which carry no colour information anyway.

Keypoints are detected on the grey image with the base method; the base descriptor is
computed on M1, M2, M3 at the same keypoints, the three are concatenated (3 x 128 = 384 for
SIFT, 3 x 64 = 192 for SURF) and reduced with a trained PCA basis (equations 18-19) to 128
(SIFT) or 64 (SURF) -- the base descriptor's own length, so matching costs the same as the
grey base. ``reduce=False`` keeps the full concatenation.
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from vision.features.patches import detect_sift
from vision.features.pca import PcaBasis, default_basis
from vision.features.types import Features

__all__ = [
    "EPS",
    "M_SCALE",
    "colour_features",
    "colour_raw_sift",
    "colour_raw_surf",
    "describe_colour_sift",
    "m_images",
    "m_images_uint8",
]

#: Guard of the logarithms, in digital numbers of the uint8 image.
EPS = 1.0
#: Fixed mapping of an m-image to uint8 for OpenCV's SIFT: ``128 + M_SCALE * M``, clipped.
#: It covers log ratios in [-3.2, +3.2] (colour ratios up to 24:1 around the image's median)
#: with a step of 1/40 = 0.025 (2.5 % in the ratio); stronger ratios saturate.
M_SCALE = 40.0
_BASES = {"sift": 128, "surf": 64}
_VERSION_RAW = "color-{base}-raw-1"


def m_images(rgb: np.ndarray, *, eps: float = EPS) -> np.ndarray:
    """The log colour-ratio images M1, M2, M3 (chapter equations 15-17), median-centred.

    Parameters
    ----------
    rgb : ndarray of shape (H, W, 3)
        RGB image, uint8 or float (values in digital numbers).
    eps : float
        Added to each channel before the logarithm (> 0).

    Returns
    -------
    ndarray of shape (3, H, W), float32
        ``M1 = log(R/G)``, ``M2 = log(R/B)``, ``M3 = log(G/B)`` minus their medians. The
        difference of ``Mi`` between neighbouring pixels is ``log mi`` of equation 15.
    """
    rgb = np.asarray(rgb)
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ValueError(f"rgb must have shape (H, W, 3), got {rgb.shape}")
    if not eps > 0:
        raise ValueError(f"eps must be > 0, got {eps!r}")
    lg = np.log(rgb.astype(np.float32) + np.float32(eps))
    r, g, b = lg[..., 0], lg[..., 1], lg[..., 2]
    m = np.stack([r - g, r - b, g - b])
    return (m - np.median(m.reshape(3, -1), axis=1)[:, None, None]).astype(np.float32)


def m_images_uint8(m: np.ndarray) -> np.ndarray:
    """Map m-images to uint8 by the fixed ``128 + 40 M`` (:data:`M_SCALE`), rounded and
    clipped, for OpenCV's SIFT, which reads only 8-bit images."""
    return np.clip(np.rint(128.0 + M_SCALE * np.asarray(m)), 0, 255).astype(np.uint8)


def describe_colour_sift(rgb: np.ndarray, keypoints: list[cv2.KeyPoint]) -> np.ndarray:
    """OpenCV SIFT descriptors of the three uint8-mapped m-images at given OpenCV keypoints
    (as returned by its detector, with the packed octave), concatenated: (N, 384) float32."""
    if not keypoints:
        return np.zeros((0, 384), np.float32)
    sift = cv2.SIFT_create()  # type: ignore[attr-defined]
    parts = []
    for mu8 in m_images_uint8(m_images(rgb)):
        kk, d = sift.compute(mu8, list(keypoints))
        if d is None or len(kk) != len(keypoints):  # OpenCV keeps every given keypoint
            raise RuntimeError("OpenCV SIFT dropped keypoints while describing an m-image")
        parts.append(d)
    return np.concatenate(parts, axis=1).astype(np.float32)


def colour_raw_sift(rgb: np.ndarray, grey: np.ndarray, **detect) -> tuple:
    """Keypoints on ``grey`` and OpenCV SIFT descriptors on the three m-images, concatenated.

    Returns ``(Keypoints, ndarray (N, 384) float32)``; ``detect`` goes to the SIFT detector
    (``max_features``, ``threshold``, ``mask``).
    """
    kp, cvk = detect_sift(grey, **detect)
    return kp, describe_colour_sift(rgb, cvk)


def colour_raw_surf(
    rgb: np.ndarray,
    grey: np.ndarray,
    *,
    upright: bool = False,
    extended: bool = False,
    **detect,
) -> tuple:
    """Keypoints of our SURF on ``grey`` and SURF descriptors of the three (float) m-images,
    concatenated: ``(Keypoints, ndarray (N, 192) float32)`` (384 with ``extended``)."""
    from vision.features.surf import surf_describe, surf_keypoints

    kp = surf_keypoints(grey, upright=upright, **detect)
    width = 128 if extended else 64
    if len(kp) == 0:
        return kp, np.zeros((0, 3 * width), np.float32)
    parts = [
        np.asarray(surf_describe(m, kp, upright=upright, extended=extended), np.float32)
        for m in m_images(rgb)
    ]
    return kp, np.concatenate(parts, axis=1)


def colour_features(
    rgb: np.ndarray,
    *,
    base: str = "sift",
    reduce: bool = True,
    basis: PcaBasis | None = None,
    max_features: int | None = None,
    threshold: float | None = None,
    mask: np.ndarray | None = None,
    **base_options,
) -> Features:
    """Colour-invariant descriptor of the chapter (equations 15-19) on a SIFT or SURF base.

    Parameters
    ----------
    rgb : ndarray of shape (H, W, 3), uint8
    base : {"sift", "surf"}
        Base detector/descriptor (OpenCV SIFT; VisionCell's SURF).
    reduce : bool
        Project the concatenated descriptor with the PCA basis (default); False keeps all
        384 (SIFT) / 192 (SURF) dimensions.
    basis : PcaBasis, optional
        Default: the shipped ``color-sift`` / ``color-surf`` basis.
    max_features, threshold, mask
        Detector options of the base method (on the grey image).
    **base_options
        For SURF: ``upright``, ``extended``, ``n_octaves``.

    Returns
    -------
    Features
        Method ``"color-sift"`` or ``"color-surf"``.
    """
    if base not in _BASES:
        raise ValueError(f"base must be one of {', '.join(_BASES)}, got {base!r}")
    rgb = np.asarray(rgb)
    if rgb.dtype != np.uint8 or rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ValueError(f"rgb must be a uint8 (H, W, 3) image, got {rgb.dtype} {rgb.shape}")
    method = f"color-{base}"
    if reduce and basis is None:
        basis = default_basis(method)
    grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    detect: dict[str, Any] = {"max_features": max_features, "threshold": threshold, "mask": mask}
    if base == "sift":
        if base_options:
            raise ValueError(f"unknown options for color-sift: {', '.join(base_options)}")
        kp, raw = colour_raw_sift(rgb, grey, **detect)
    else:
        detect = {k: v for k, v in detect.items() if v is not None}
        kp, raw = colour_raw_surf(rgb, grey, **detect, **base_options)
    if not reduce:
        return Features(kp, raw, method, _VERSION_RAW.format(base=base), False, grey.shape)
    assert basis is not None  # set above whenever reduce is true
    if basis.dim_in != raw.shape[1]:
        raise ValueError(
            f"basis {basis.kind!r} reduces {basis.dim_in}-dim vectors, {method} gives "
            f"{raw.shape[1]}"
        )
    return Features(kp, basis.project(raw), method, basis.version, False, grey.shape)
