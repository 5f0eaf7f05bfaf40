"""Synthetic images and known transforms for the descriptor tests."""

from __future__ import annotations

import cv2
import numpy as np

from vision.features import Features


def textured_rgb(seed: int = 0, size: int = 320) -> np.ndarray:
    """A seeded colour texture: blurred noise at two scales, a different mix per channel,
    values in [20, 200] (room for gains without saturation)."""
    rng = np.random.default_rng(seed)
    layers = []
    for sigma in (2.5, 6.0):
        for _ in range(3):
            n = cv2.GaussianBlur(rng.normal(size=(size, size)).astype(np.float32), (0, 0), sigma)
            layers.append(n / n.std())
    layers = np.stack(layers, axis=-1)
    mix = rng.normal(size=(layers.shape[-1], 3))
    mix[[0, 3]] = 1.5  # one fine and one coarse layer shared by all channels: grey contrast
    img = layers @ mix
    img = (img - img.min(axis=(0, 1))) / np.ptp(img, axis=(0, 1))
    return np.clip(20 + 180 * img, 0, 255).astype(np.uint8)


def similarity(size: int, angle_deg: float, scale: float) -> np.ndarray:
    """3x3 rotation (counter-clockwise on screen) and scale about the image centre."""
    c = (size - 1) / 2
    return np.vstack([cv2.getRotationMatrix2D((c, c), angle_deg, scale), [0, 0, 1]])


def perspective(size: int) -> np.ndarray:
    """A moderate homography (about 20 degrees of out-of-plane tilt)."""
    s = size - 1
    src = np.float32([[0, 0], [s, 0], [s, s], [0, s]])
    dst = np.float32([[0.06 * s, 0.04 * s], [0.94 * s, 0.0], [s, s], [0.02 * s, 0.9 * s]])
    return cv2.getPerspectiveTransform(src, dst)


def warp(img: np.ndarray, H: np.ndarray) -> np.ndarray:
    h, w = img.shape[:2]
    return cv2.warpPerspective(img, H, (w, h), flags=cv2.INTER_LINEAR, borderValue=(110,) * 3)


def match_quality(a: Features, b: Features, H: np.ndarray, tol: float = 2.0) -> dict:
    """Nearest-neighbour accuracy on ground-truth correspondences (keypoints of ``a`` that
    ``H`` maps within ``tol`` px of a keypoint of ``b``), and the mean distance of
    corresponding descriptors relative to that of random pairs."""
    pa = cv2.perspectiveTransform(a.keypoints.xy[None].astype(np.float64), H)[0]
    d = np.linalg.norm(pa[:, None] - b.keypoints.xy[None], axis=2)
    gt = d.min(axis=1) < tol
    da, db = a.descriptors.astype(np.float64), b.descriptors.astype(np.float64)
    dist = np.linalg.norm(da[:, None] - db[None], axis=2)
    nn = dist.argmin(axis=1)
    correct = d[np.arange(len(nn)), nn] < tol
    rng = np.random.default_rng(0)
    rnd = dist[rng.integers(0, len(da), 500), rng.integers(0, len(db), 500)].mean()
    pair = dist[np.nonzero(gt)[0], d[gt].argmin(axis=1)].mean()
    return {
        "n_gt": int(gt.sum()),
        "accuracy": float(correct[gt].mean()),
        "chance": float(1 / len(db)),
        "pair_over_random": float(pair / rnd),
    }
