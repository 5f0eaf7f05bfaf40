"""Small synthetic textured images for the recognition tests (seeded, fast to describe)."""

from __future__ import annotations

import cv2
import numpy as np


def textured(seed: int, size: int = 160) -> np.ndarray:
    """A grey (size, size) uint8 image of random filled shapes: many SIFT features."""
    rng = np.random.default_rng(seed)
    img = np.full((size, size), 128, np.uint8)
    for _ in range(40):
        c = tuple(int(v) for v in rng.integers(8, size - 8, 2))
        grey = int(rng.integers(0, 256))
        if rng.random() < 0.5:
            axes = tuple(int(v) for v in rng.integers(3, size // 8, 2))
            cv2.ellipse(img, c, axes, float(rng.uniform(0, 180)), 0, 360, grey, -1)
        else:
            d = rng.integers(3, size // 8, 2)
            cv2.rectangle(img, c, (int(c[0] + d[0]), int(c[1] + d[1])), grey, -1)
    return cv2.GaussianBlur(img, (3, 3), 0.8)


def rotated(image: np.ndarray, angle_deg: float, scale: float = 1.0) -> np.ndarray:
    """``image`` rotated about its centre (border replicated)."""
    h, w = image.shape[:2]
    M = cv2.getRotationMatrix2D((w / 2, h / 2), angle_deg, scale)
    return cv2.warpAffine(image, M, (w, h), borderMode=cv2.BORDER_REPLICATE)


def noise(seed: int, size: int = 160) -> np.ndarray:
    """Smoothed random noise: features that belong to no trained model."""
    rng = np.random.default_rng(seed)
    img = rng.integers(0, 256, (size // 4, size // 4)).astype(np.uint8)
    return cv2.resize(img, (size, size), interpolation=cv2.INTER_CUBIC)
