"""Synthetic images with known boundaries for the segmentation tests."""

from __future__ import annotations

import numpy as np


def ellipse_image(
    shape=(200, 240),
    center=(120.0, 100.0),
    axes=(60.0, 40.0),
    *,
    inside=0.7,
    outside=0.3,
    noise=0.08,
    seed=0,
):
    """Float image in [0, 1]: an ellipse ``inside`` on ``outside`` plus Gaussian noise.

    Returns the image and the true mask (pixel centres inside the ellipse).
    """
    h, w = shape
    yy, xx = np.mgrid[:h, :w]
    mask = ((xx - center[0]) / axes[0]) ** 2 + ((yy - center[1]) / axes[1]) ** 2 < 1.0
    rng = np.random.default_rng(seed)
    img = np.where(mask, inside, outside) + rng.normal(0.0, noise, size=mask.shape)
    return np.clip(img, 0.0, 1.0), mask


def distance_to_ellipse(points, center, axes, samples=20000):
    """Distance of (x, y) points to the ellipse outline (dense sampling of the outline)."""
    t = np.linspace(0.0, 2.0 * np.pi, samples, endpoint=False)
    outline = np.stack([center[0] + axes[0] * np.cos(t), center[1] + axes[1] * np.sin(t)], 1)
    d = np.linalg.norm(points[:, None, :] - outline[None, ::10, :], axis=2)
    near = np.argmin(d, axis=1) * 10
    # Refine around the coarse nearest sample.
    idx = (near[:, None] + np.arange(-10, 11)[None, :]) % samples
    return np.min(np.linalg.norm(points[:, None, :] - outline[idx], axis=2), axis=1)
