"""Regression (issue 17): on a dark, noise-free 8-bit image of flat colour patches (an SFU
Macbeth chart under a dim lamp), the noise model took each pixel's quantisation as
independent noise, predicted as much gradient energy from it as the real colour edges give,
and weighted the colour blocks ~0 -- though a flat patch rounds alike at every pixel and holds
no noise. The same chart four times as bright got high weights, so the colour blocks of one
surface differed between the exposures and pushed true matches apart."""

from __future__ import annotations

import numpy as np

from vision.features.colour_joint import _JOINT_M, _m_images_and_noise, block_snr_weight
from vision.features.types import Keypoints


def _chart(gain: float) -> np.ndarray:
    """A 4 x 4 chart of flat patches, 40 px each, linear values ``gain`` times a dark base."""
    rng = np.random.default_rng(1)
    base = rng.uniform([2.0, 4.0, 20.0], [12.0, 16.0, 60.0], (4, 4, 3))
    img = np.kron(base, np.ones((40, 40, 1)))
    return np.clip(np.rint(gain * img), 0, 255).astype(np.uint8)


def test_flat_dark_patches_keep_their_colour_weight() -> None:
    colour = {"transfer": "linear", "white_level": 255.0, "noise_floor": 3.0, "saturation": 0.98}
    # Keypoints on the inner patch corners, windows of side 40 px.
    xy = np.array([[40.0 * i, 40.0 * j] for i in (1, 2, 3) for j in (1, 2, 3)])
    kp = Keypoints(
        xy, np.full(len(xy), 40.0), np.zeros(len(xy)), np.ones(len(xy)), np.zeros(len(xy), np.int32)
    )
    weights = []
    for gain in (0.5, 2.0):
        m, var, quant = _m_images_and_noise(_chart(gain), **colour, pairs=_JOINT_M)
        weights.append(block_snr_weight(m, var, kp, radius_per_size=0.5, quant_var=quant))
    dark, bright = weights
    # Noise-free patches: the colour edges are mostly signal at either exposure; the dark
    # one's rounding (1-6 DN in red) errs by each patch's level, which can only lower it.
    assert np.median(dark) > 0.8, dark
    assert np.median(bright) > 0.95, bright
    assert np.all(dark <= bright + 0.02), (dark, bright)
