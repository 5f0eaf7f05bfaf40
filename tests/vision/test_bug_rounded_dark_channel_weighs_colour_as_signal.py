"""Regression (issue 17): on the SFU Macbeth chart under the blue-filtered lamp the red channel
is 0-10 DN, noise-free. The M1 = log(R/G) blocks weighed 0.9 there, as in the bright
reference, because the noise model dropped the quantisation where the sensor noise does not
dither it -- yet the rounding still errs by each patch's level, so the M1 descriptors of one
corner differed between the lamps (distance 0.35-0.85 of unit vectors) and pushed a true match
behind four false ones. The coherent rounding must lower the weight of such a channel."""

from __future__ import annotations

import numpy as np

from vision.features.colour_joint import _JOINT_M, _m_images_and_noise, block_snr_weight
from vision.features.types import Keypoints

_PATCH, _GAP = 36, 8  # px


def _chart_scene() -> np.ndarray:
    """Linear values of a 5 x 5 chart of flat patches on a dark border at 10 % of each patch."""
    rng = np.random.default_rng(2)
    base = rng.uniform(40.0, 120.0, (5, 5, 3))
    pitch = _PATCH + _GAP
    img = np.zeros((5 * pitch, 5 * pitch, 3))
    for i in range(5):
        for j in range(5):
            img[i * pitch : (i + 1) * pitch, j * pitch : (j + 1) * pitch] = 0.1 * base[i, j]
            img[i * pitch + _GAP : (i + 1) * pitch, j * pitch + _GAP : (j + 1) * pitch] = base[i, j]
    return img


def test_rounded_dark_red_lowers_the_m1_weight_as_much_as_it_errs() -> None:
    colour = {"transfer": "linear", "white_level": 255.0, "noise_floor": 3.0, "saturation": 0.98}
    scene = _chart_scene()
    pitch = _PATCH + _GAP
    xy = np.array(
        [[pitch * i + _GAP / 2, pitch * j + _GAP / 2] for i in range(1, 5) for j in range(1, 5)]
    )
    kp = Keypoints(
        xy, np.full(len(xy), 50.0), np.zeros(len(xy)), np.ones(len(xy)), np.zeros(len(xy), np.int32)
    )
    ms, ws = [], []
    # The same scene under two lamps (a diagonal change): bright, and with red 25x dimmer.
    for gains in ((1.5, 1.0, 1.0), (0.06, 0.5, 1.0)):
        img = np.clip(np.rint(scene * np.array(gains)), 0, 255).astype(np.uint8)
        m, var, quant = _m_images_and_noise(img, **colour, pairs=_JOINT_M)
        ms.append(m[0])
        ws.append(block_snr_weight(m, var, kp, radius_per_size=0.5, quant_var=quant)[:, 0])
    bright, dim = ws
    # How much of the dim M1's variation in each window is error (against the bright one,
    # whose rounding is 25x smaller relative to red): 1 - that share is what the weight says.
    err = ms[1] - ms[0]
    r = 25
    held = []
    for x, y in np.rint(xy).astype(int):
        win = np.s_[y - r : y + r + 1, x - r : x + r + 1]
        held.append(1.0 - err[win].var() / ms[1][win].var())
    assert np.median(bright) > 0.95, bright
    assert dim.mean() < bright.mean() - 0.2, (dim, bright)
    assert dim.mean() < np.mean(held) + 0.25, (dim, held)
