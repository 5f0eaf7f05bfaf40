"""GLOH, the Gradient Location and Orientation Histogram (Mikolajczyk and Schmid, "A
Performance Evaluation of Local Descriptors", PAMI 27(10), 2005), chapter section 3.3.1.

At SIFT keypoints (OpenCV's DoG detector, orientation normalised), gradients of a 41x41
patch are binned on a log-polar location grid: a centre disc of radius 6 and two rings
(6-11, 11-15) of 8 angular sectors each (17 location bins), times 16 gradient-orientation
bins = 272 values; normalised like SIFT and reduced to 128 by a trained PCA basis (chapter
equations 18-19).
"""

from __future__ import annotations

import numpy as np

from vision.features.patches import patch_gradients, reduced_sift_features, sample_patches
from vision.features.pca import PcaBasis
from vision.features.types import Features, Keypoints

__all__ = ["GLOH_DIM", "RADII", "gloh_features", "gloh_raw"]

#: Radii of the log-polar grid in patch samples (Mikolajczyk and Schmid: 6, 11 and 15).
RADII = (6.0, 11.0, 15.0)
N_SECTORS = 8
N_ORI = 16
N_LOC = 1 + 2 * N_SECTORS
GLOH_DIM = N_LOC * N_ORI
_PATCH = 41
#: Sample spacing per keypoint size (= 2 sigma): the outer radius 15 samples is 3 size =
#: 6 sigma, the half-width of SIFT's descriptor window.
STEP_PER_SIZE = 0.2
_WEIGHT_SIGMA = 10.0  # Gaussian weight on gradient magnitude, in samples
_RAW_VERSION = "gloh-raw-1"


def _layout() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per interior sample: two (location bin, weight) pairs (soft in the angular
    direction) and the Gaussian weight; samples outside radius 15 get weight 0."""
    g = np.arange(_PATCH - 2, dtype=np.float64) - (_PATCH - 3) / 2
    u, v = np.meshgrid(g, g)
    r = np.hypot(u, v)
    # Sector angle measured counter-clockwise on screen in the patch frame (v points down).
    t = np.mod(np.arctan2(-v, u), 2 * np.pi) / (2 * np.pi / N_SECTORS) - 0.5
    s0 = np.floor(t)
    w1 = t - s0
    s0 = s0.astype(int) % N_SECTORS
    s1 = (s0 + 1) % N_SECTORS
    ring = np.where(r < RADII[0], 0, np.where(r < RADII[1], 1, 2))
    base = np.where(ring == 1, 1, 1 + N_SECTORS)
    loc0 = np.where(ring == 0, 0, base + s0)
    loc1 = np.where(ring == 0, 0, base + s1)
    wg = np.exp(-(r**2) / (2 * _WEIGHT_SIGMA**2)) * (r <= RADII[2])
    return (
        np.stack([loc0, loc1]).reshape(2, -1),
        np.stack([1 - w1, w1]).reshape(2, -1),
        wg.reshape(-1),
        (r <= RADII[2]).reshape(-1),
    )


_LOC, _LOC_W, _GAUSS, _INSIDE = _layout()


def gloh_raw(grey: np.ndarray, kp: Keypoints) -> np.ndarray:
    """Unreduced 272-dim GLOH histograms, SIFT-normalised (unit length, clipped at 0.2,
    unit length again), orientation bins linearly interpolated.

    Parameters
    ----------
    grey : ndarray of shape (H, W)
    kp : Keypoints

    Returns
    -------
    ndarray of shape (N, 272), float32
        Index ``location * 16 + orientation``; location 0 is the centre, 1-8 the middle ring,
        9-16 the outer ring (sectors counter-clockwise from the keypoint orientation).
    """
    n = len(kp)
    if n == 0:
        return np.zeros((0, GLOH_DIM), np.float32)
    patches = sample_patches(grey, kp, size=_PATCH, step_per_size=STEP_PER_SIZE)
    gx, gy = patch_gradients(patches)
    inside = _INSIDE
    gx = gx.reshape(n, -1)[:, inside]
    gy = gy.reshape(n, -1)[:, inside]
    mag = np.hypot(gx, gy) * _GAUSS[inside]
    # Orientation counter-clockwise on screen in the patch frame (rows point down).
    o = np.mod(np.arctan2(-gy, gx), 2 * np.pi) / (2 * np.pi / N_ORI)
    o0 = np.floor(o)
    wo1 = o - o0
    o0 = o0.astype(np.int64) % N_ORI
    o1 = (o0 + 1) % N_ORI
    offs = (np.arange(n, dtype=np.int64) * GLOH_DIM)[:, None]
    hist = np.zeros(n * GLOH_DIM, np.float64)
    for li in range(2):
        loc = _LOC[li][inside][None, :] * N_ORI + offs
        wl = _LOC_W[li][inside][None, :] * mag
        for ob, wo in ((o0, 1 - wo1), (o1, wo1)):
            hist += np.bincount(
                (loc + ob).ravel(), weights=(wl * wo).ravel(), minlength=n * GLOH_DIM
            )
    h = hist.reshape(n, GLOH_DIM)
    h /= np.maximum(np.linalg.norm(h, axis=1, keepdims=True), 1e-12)
    h = np.minimum(h, 0.2)
    h /= np.maximum(np.linalg.norm(h, axis=1, keepdims=True), 1e-12)
    return h.astype(np.float32)


def gloh_features(
    grey: np.ndarray,
    *,
    max_features: int | None = None,
    threshold: float | None = None,
    mask: np.ndarray | None = None,
    basis: PcaBasis | None = None,
    reduce: bool = True,
) -> Features:
    """Detect DoG keypoints and compute GLOH descriptors (Mikolajczyk and Schmid 2005).

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
        Projection basis (272 -> k); default: the shipped ``gloh`` basis (k = 128).
    reduce : bool
        False returns the unreduced 272-dim histograms.

    Returns
    -------
    Features
        Method ``"gloh"``; the version is the basis's (it includes its hash).
    """
    return reduced_sift_features(
        grey,
        "gloh",
        gloh_raw,
        GLOH_DIM,
        _RAW_VERSION,
        max_features=max_features,
        threshold=threshold,
        mask=mask,
        basis=basis,
        reduce=reduce,
    )
