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

Keypoints are detected on the grey image with the base method, the same keypoints the grey
base finds. Two layouts of the descriptor (``layout=``):

* ``"chapter"``: the base descriptor of M1, M2, M3 at the keypoints, concatenated (3 x 128 =
  384 for SIFT, 3 x 64 = 192 for SURF), as first built. It wins under synthetic
  changes and loses to the grey base under real light changes;
* ``"joint"`` (default, :mod:`vision.features.colour_joint`): the grey base descriptor, then
  the descriptors of *noise-aware* m-images M1 and M3 (a floor set from the measured noise
  before the logarithm, clipped pixels neutralised, optional sRGB linearisation), each
  weighted by its signal over the sensor noise expected there (0 where colour holds only
  noise, so the descriptor is then exactly the grey one) -- same length, 384 / 192.

The chapter's layout is reduced with its trained PCA basis (equations 18-19) to 128 (SIFT)
or 64 (SURF). The joint layout keeps its grey block whole and reduces the two colour blocks
with their basis to 32 (SIFT) or 16 (SURF): 160 / 80 dimensions, and where the colour blocks
are 0 so is their projection (no mean shift), so colour can only add to the grey distances.
``reduce=False`` keeps the full concatenation. The colour ratios are illuminant-invariant for
linear sensor values only: an sRGB (gamma) camera needs ``transfer="srgb"``; uint16 input is
taken as linear values with ``white_level`` (default 65535) as full scale.
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from vision.features.colour_input import (
    M_SCALE,
    TRANSFERS,
    check_white_level,
    m_images_uint8,
    srgb8_from_linear,
)
from vision.features.colour_joint import NOISE_FLOOR, SATURATION, joint_raw
from vision.features.patches import detect_sift
from vision.features.pca import PcaBasis, default_basis
from vision.features.types import Features

__all__ = [
    "COLOUR_WEIGHT",
    "EPS",
    "LAYOUTS",
    "M_SCALE",
    "NOISE_FLOOR",
    "SATURATION",
    "colour_features",
    "colour_raw_sift",
    "colour_raw_surf",
    "describe_colour_sift",
    "detection_grey",
    "m_images",
    "m_images_uint8",
]

#: Guard of the logarithms, in digital numbers of the uint8 image.
EPS = 1.0
#: Descriptor layouts: ``"joint"`` (default) is the grey base descriptor followed by the
#: contrast-weighted descriptors of the noise-aware m-images M1 and M3; ``"chapter"`` the
#: three m-image descriptors of equations 15-17 alone, as first built.
LAYOUTS = ("joint", "chapter")
#: Weight of the m-image blocks against the grey block in the joint layout (times each
#: block's noise weight), per base: chosen by leave-one-scene-out cross-validation over
#: {0.1, 0.25, 0.5, 1, 1.5} on the real illumination scenes
#: (``python -m benchmarks.registration_colour_cv``): 0.25 in all 23 folds for SIFT,
#: 0.1 in 22 of 23 for SURF.
COLOUR_WEIGHT: dict[str, float] = {"sift": 0.25, "surf": 0.1}
_BASES = {"sift": 128, "surf": 64}
_VERSION_RAW = "color-{base}-raw-1"
_VERSION_JOINT_RAW = "color-{base}-joint-raw-1"


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


def _check_options(
    layout: str, transfer: str, noise_floor: float, saturation: float, colour_weight: float
) -> None:
    if layout not in LAYOUTS:
        raise ValueError(f"layout must be one of {', '.join(LAYOUTS)}, got {layout!r}")
    if transfer not in TRANSFERS:
        raise ValueError(f"transfer must be one of {', '.join(TRANSFERS)}, got {transfer!r}")
    for name, v, lo, hi in (
        ("noise_floor", noise_floor, 0.0, 100.0),
        ("saturation", saturation, 0.5, 1.0),
        ("colour_weight", colour_weight, 0.0, 10.0),
    ):
        if isinstance(v, bool) or not isinstance(v, int | float | np.number):
            raise ValueError(f"{name} must be a number, got {v!r}")
        if not (np.isfinite(v) and lo <= v <= hi):
            raise ValueError(f"{name} must be in [{lo:g}, {hi:g}], got {v!r}")
    if layout == "chapter" and transfer != "linear":
        raise ValueError(
            f"layout 'chapter' reads the values as given; transfer {transfer!r} needs layout 'joint'"
        )


def detection_grey(rgb: np.ndarray, *, white_level: float | None = None) -> np.ndarray:
    """The grey uint8 image the colour methods detect keypoints on: ITU-R BT.601 grey of the
    image as delivered for uint8 input (the grey base sees the same); for uint16 linear input,
    of its 8-bit sRGB encoding (:func:`~vision.features.colour_input.srgb8_from_linear`)."""
    if rgb.dtype == np.uint16:
        rgb = srgb8_from_linear(rgb, white_level=white_level)
    return cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)


def colour_features(
    rgb: np.ndarray,
    *,
    base: str = "sift",
    reduce: bool = True,
    basis: PcaBasis | None = None,
    max_features: int | None = None,
    threshold: float | None = None,
    mask: np.ndarray | None = None,
    layout: str = "joint",
    transfer: str = "linear",
    white_level: float | None = None,
    noise_floor: float = NOISE_FLOOR,
    saturation: float = SATURATION,
    colour_weight: float | None = None,
    **base_options,
) -> Features:
    """Colour-invariant descriptor of the chapter (equations 15-19) on a SIFT or SURF base.

    Parameters
    ----------
    rgb : ndarray of shape (H, W, 3), uint8 or uint16
        RGB image; uint16 holds linear sensor values (keypoints are then detected on its
        8-bit sRGB encoding, :func:`detection_grey`).
    base : {"sift", "surf"}
        Base detector/descriptor (OpenCV SIFT; VisionCell's SURF).
    reduce : bool
        Project with the PCA basis (default): the joint layout keeps its grey block and
        reduces its colour blocks (160 dimensions for SIFT, 80 for SURF), the chapter's
        layout reduces all of it (128, 64). False keeps all 384 (SIFT) / 192 (SURF).
    basis : PcaBasis, optional
        Default: the shipped basis of the layout (``color-sift``, ``color-surf``, or
        ``color-sift-chapter``, ``color-surf-chapter``).
    max_features, threshold, mask
        Detector options of the base method (on the grey image).
    layout : {"joint", "chapter"}
        ``"joint"``: grey base descriptor, then the descriptors of the noise-aware m-images
        M1 = log(R/G) and M3 = log(G/B), each weighted by its signal over the expected
        sensor noise (:func:`~vision.features.colour_joint.block_snr_weight`) times
        ``colour_weight``. ``"chapter"``: the descriptors of
        M1, M2, M3 with a 1 DN guard, as in equations 15-17.
    transfer : {"linear", "srgb"}
        How the values encode light: ``"srgb"`` linearises 8-bit sRGB with the IEC 61966-2-1
        curve before the ratios (for cameras that apply a gamma); the ratios are invariant to
        the illuminant only on linear values.
    white_level : float, optional
        Value of full scale (default the dtype's maximum: 255 or 65535).
    noise_floor : float
        Floor added before the logarithms, in units of the image's measured noise sigma
        (quantisation included); 0 keeps only a 1e-6 guard.
    saturation : float
        Relative level in [0.5, 1] at which a channel counts as clipped; 1 turns the mask off.
    colour_weight : float, optional
        Weight of the m-image blocks against the grey block (joint layout), in [0, 10];
        default :data:`COLOUR_WEIGHT` of the base.
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
    if rgb.dtype not in (np.uint8, np.uint16) or rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ValueError(
            f"rgb must be a uint8 (H, W, 3) image (or uint16 linear values), got "
            f"{rgb.dtype} {rgb.shape}"
        )
    if colour_weight is None:
        colour_weight = COLOUR_WEIGHT[base]
    _check_options(layout, transfer, noise_floor, saturation, colour_weight)
    white_level = check_white_level(rgb, white_level)
    method = f"color-{base}"
    kind = method if layout == "joint" else f"{method}-chapter"
    if reduce and basis is None:
        basis = default_basis(kind)
    grey = detection_grey(rgb, white_level=white_level)
    detect: dict[str, Any] = {"max_features": max_features, "threshold": threshold, "mask": mask}
    if base == "sift" and base_options:
        raise ValueError(f"unknown options for color-sift: {', '.join(base_options)}")
    if layout == "joint":
        colour = {
            "transfer": transfer,
            "white_level": white_level,
            "noise_floor": float(noise_floor),
            "saturation": float(saturation),
            "colour_weight": float(colour_weight),
        }
        kp, raw = joint_raw(rgb, grey, base, detect, base_options, colour)
        raw_version = _VERSION_JOINT_RAW.format(base=base)
    elif base == "sift":
        kp, raw = colour_raw_sift(rgb, grey, **detect)
        raw_version = _VERSION_RAW.format(base=base)
    else:
        detect = {k: v for k, v in detect.items() if v is not None}
        kp, raw = colour_raw_surf(rgb, grey, **detect, **base_options)
        raw_version = _VERSION_RAW.format(base=base)
    if not reduce:
        return Features(kp, raw, method, raw_version, False, grey.shape)
    assert basis is not None  # set above whenever reduce is true
    grey_dim = raw.shape[1] // 3 if layout == "joint" else 0
    if basis.dim_in != raw.shape[1] - grey_dim:
        raise ValueError(
            f"basis {basis.kind!r} reduces {basis.dim_in}-dim vectors, {method} gives "
            f"{raw.shape[1] - grey_dim}"
        )
    if layout == "chapter":
        return Features(kp, basis.project(raw), method, basis.version, False, grey.shape)
    # Joint: the grey block whole, the colour blocks projected on the basis without the
    # mean shift of equation 18 (distances do not depend on it), so colour blocks that the
    # noise weights set to 0 stay 0 and the descriptor is then exactly the grey one.
    reduced = np.concatenate([raw[:, :grey_dim], raw[:, grey_dim:] @ basis.components], axis=1)
    return Features(kp, reduced.astype(np.float32), method, basis.version, False, grey.shape)
