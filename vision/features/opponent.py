"""OpponentSIFT (van de Sande, Gevers and Snoek, "Evaluating Color Descriptors for Object and
Scene Recognition", IEEE TPAMI 32(9), 2010, section 4.1): a further colour baseline for the
chapter's colour-ratio descriptor (section 3.4).

The opponent colour space is

    O1 = (R - G) / sqrt(2),   O2 = (R + G - 2B) / sqrt(6),   O3 = (R + G + B) / sqrt(3);

O3 carries the intensity, O1 and O2 the colour. OpponentSIFT is the SIFT descriptor of each
channel at the same keypoints, concatenated (3 x 128 = 384). Van de Sande et al. derive that
O1 and O2 are invariant to a light intensity offset (shift-invariant) and that SIFT's
normalisation adds invariance to intensity scaling per channel; it is not invariant to a
change of the light's colour, which is what makes it a baseline here. Keypoints are OpenCV's
DoG keypoints of the grey image, the same as ``extract(image, "sift")`` finds, so that only the
descriptor differs. OpenCV's SIFT reads 8-bit images, so the channels are mapped affinely to
[0, 255]: ``(R - G) / 2 + 127.5``, ``(R + G - 2B) / 4 + 127.5`` and ``(R + G + B) / 3`` (SIFT
normalises each channel's descriptor, so the scale factors do not matter).
"""

from __future__ import annotations

import cv2
import numpy as np

from vision.features.types import Features

__all__ = ["OPPONENT_VERSION", "opponent_channels", "opponent_sift_features"]

#: Descriptor version (OpenCV SIFT per opponent channel, layout O1, O2, O3).
OPPONENT_VERSION = f"opponent-sift-1-opencv-{cv2.__version__}"


def opponent_channels(rgb: np.ndarray) -> np.ndarray:
    """The opponent channels O1, O2, O3 of an RGB uint8 image mapped to uint8 (3, H, W)."""
    rgb = np.asarray(rgb)
    if rgb.dtype != np.uint8 or rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ValueError(f"rgb must be a uint8 (H, W, 3) image, got {rgb.dtype} {rgb.shape}")
    f = rgb.astype(np.float32)
    r, g, b = f[..., 0], f[..., 1], f[..., 2]
    o = np.stack([(r - g) / 2 + 127.5, (r + g - 2 * b) / 4 + 127.5, (r + g + b) / 3])
    return np.clip(np.rint(o), 0, 255).astype(np.uint8)


def opponent_sift_features(
    rgb: np.ndarray,
    *,
    max_features: int | None = None,
    threshold: float | None = None,
    mask: np.ndarray | None = None,
) -> Features:
    """OpponentSIFT descriptors (van de Sande et al. 2010) at the grey image's SIFT keypoints.

    Parameters
    ----------
    rgb : ndarray of shape (H, W, 3), uint8
    max_features, threshold, mask
        As for ``extract(image, "sift")``.

    Returns
    -------
    Features
        Method ``"opponent-sift"``, descriptors (N, 384) float32: O1, O2, O3 blocks.
    """
    from vision.features.colour_joint import _sift_detect_describe

    channels = opponent_channels(rgb)
    grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    kp, cvk, _ = _sift_detect_describe(
        grey, max_features=max_features, threshold=threshold, mask=mask
    )
    if len(kp) == 0:
        return Features(
            kp, np.zeros((0, 384), np.float32), "opponent-sift", OPPONENT_VERSION, False, grey.shape
        )
    sift = cv2.SIFT_create()  # type: ignore[attr-defined]  # missing from the OpenCV stubs
    parts = []
    for ch in channels:
        got, d = sift.compute(ch, list(cvk))
        if d is None or len(got) != len(cvk):
            raise RuntimeError("OpenCV SIFT dropped keypoints while describing an opponent channel")
        parts.append(d.astype(np.float32))
    desc = np.concatenate(parts, axis=1)
    return Features(kp, desc, "opponent-sift", OPPONENT_VERSION, False, grey.shape)
