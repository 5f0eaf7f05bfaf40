"""PCA-SIFT (Ke and Sukthankar, "PCA-SIFT: A More Distinctive Representation for Local Image
Descriptors", CVPR 2004), chapter section 3.3.1.

At each DoG keypoint (OpenCV's SIFT detector gives location, scale and orientation) a 41x41
patch is sampled, rotated to the keypoint orientation and scaled to its scale; its horizontal
and vertical gradients at the 39x39 interior samples form a 3042-vector, normalised to unit
length and projected onto a trained PCA basis (chapter equations 18-19) of 36 components.
"""

from __future__ import annotations

import numpy as np

from vision.features.patches import patch_gradients, reduced_sift_features, sample_patches
from vision.features.pca import PcaBasis
from vision.features.types import Features, Keypoints

__all__ = ["PATCH_SIZE", "STEP_PER_SIZE", "pca_sift_features", "pca_sift_raw"]

#: Patch side in samples (Ke and Sukthankar: 41x41, gradients on the 39x39 interior).
PATCH_SIZE = 41
#: Sample spacing in units of OpenCV's keypoint size (= 2 sigma): the 41 samples span
#: 6 size = 12 sigma, the same support as SIFT's 4x4 grid of 3-sigma cells.
STEP_PER_SIZE = 0.15
_RAW_VERSION = "pca-sift-raw-1"


def pca_sift_raw(grey: np.ndarray, kp: Keypoints) -> np.ndarray:
    """Unreduced PCA-SIFT vectors: gradients of the normalised 41x41 patch, unit length.

    Parameters
    ----------
    grey : ndarray of shape (H, W)
        Grey image (uint8 or float).
    kp : Keypoints

    Returns
    -------
    ndarray of shape (N, 3042), float32
        ``[gx (39x39, row-major), gy (39x39)]`` per keypoint, L2-normalised (zero stays zero).
    """
    patches = sample_patches(grey, kp, size=PATCH_SIZE, step_per_size=STEP_PER_SIZE)
    gx, gy = patch_gradients(patches)
    v = np.concatenate([gx.reshape(len(kp), -1), gy.reshape(len(kp), -1)], axis=1)
    norm = np.linalg.norm(v, axis=1, keepdims=True)
    return (v / np.maximum(norm, 1e-12)).astype(np.float32)


def pca_sift_features(
    grey: np.ndarray,
    *,
    max_features: int | None = None,
    threshold: float | None = None,
    mask: np.ndarray | None = None,
    basis: PcaBasis | None = None,
    reduce: bool = True,
) -> Features:
    """Detect DoG keypoints and compute PCA-SIFT descriptors (Ke and Sukthankar 2004).

    Parameters
    ----------
    grey : ndarray of shape (H, W), uint8
    max_features : int, optional
        Keep at most this many of the strongest keypoints.
    threshold : float, optional
        SIFT ``contrastThreshold`` of the detector (OpenCV default 0.04).
    mask : ndarray of shape (H, W), optional
        Non-zero where keypoints may be detected.
    basis : PcaBasis, optional
        Projection basis (3042 -> k); default: the shipped ``pca-sift`` basis (k = 36).
    reduce : bool
        False returns the unreduced 3042-dim vectors (for comparisons).

    Returns
    -------
    Features
        Method ``"pca-sift"``; the version is the basis's (it includes its hash).
    """
    return reduced_sift_features(
        grey,
        "pca-sift",
        pca_sift_raw,
        2 * (PATCH_SIZE - 2) ** 2,
        _RAW_VERSION,
        max_features=max_features,
        threshold=threshold,
        mask=mask,
        basis=basis,
        reduce=reduce,
    )
