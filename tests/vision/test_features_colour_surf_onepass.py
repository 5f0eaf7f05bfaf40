"""The one-pass colour SURF (issue 17): the m-image blocks of color-surf described in one
pass over an interleaved integral image, with the grey detection's integral image reused,
equal the per-image SURF descriptors they replace."""

from __future__ import annotations

import numpy as np
import pytest

from vision.features import extract
from vision.features.colour import detection_grey
from vision.features.colour_input import noise_estimates, noise_floor, noise_model
from vision.features.colour_joint import (
    _JOINT_M,
    _m_images_and_noise,
    block_snr_weight,
    joint_parts,
)
from vision.features.surf import surf_describe, surf_describe_channels, surf_keypoints


def _scene(seed: int = 3) -> np.ndarray:
    """A textured colour scene with dark, clipped and flat regions (uint8 RGB)."""
    rng = np.random.default_rng(seed)
    h, w = 160, 200
    yy, xx = np.mgrid[0:h, 0:w]
    img = np.zeros((h, w, 3), np.float64)
    for _ in range(25):
        cx, cy, r = rng.uniform(0, w), rng.uniform(0, h), rng.uniform(5, 30)
        img[(xx - cx) ** 2 + (yy - cy) ** 2 < r * r] = rng.uniform(0, 300, 3)
    img[:, : w // 5] *= 0.05  # a dark strip
    img += rng.normal(0, 2.0, img.shape)
    return np.clip(img, 0, 255).astype(np.uint8)


@pytest.mark.parametrize("coarse", [False, True])
@pytest.mark.parametrize("extended", [False, True])
def test_channels_equal_per_image_descriptors(coarse: bool, extended: bool) -> None:
    rgb = _scene()
    grey = detection_grey(rgb)
    kp = surf_keypoints(grey)
    assert len(kp) > 20
    m = np.stack([rgb[..., 0] / 7.0 - rgb[..., 1] / 11.0, np.log1p(rgb[..., 2])]).astype(np.float32)
    live = np.random.default_rng(0).random((len(kp), 2)) < 0.7
    got = surf_describe_channels(m, kp, live=live, extended=extended, coarse=coarse)
    assert got.shape == (len(kp), 2, 128 if extended else 64)
    for k in range(2):
        ref = surf_describe(m[k], kp, extended=extended, coarse=coarse)
        np.testing.assert_allclose(got[live[:, k], k], ref[live[:, k]], rtol=0, atol=1e-6)
        assert not got[~live[:, k], k].any()


def test_joint_surf_blocks_unchanged() -> None:
    """joint_parts for SURF equals the composition it replaced: surf_keypoints, surf_describe
    of the grey image, and surf_describe of each m-image at its live keypoints (coarse)."""
    rgb = _scene(5)
    grey = detection_grey(rgb)
    colour = {"transfer": "linear", "white_level": 255.0, "noise_floor": 3.0, "saturation": 0.98}
    kp, g, parts, c = joint_parts(rgb, grey, "surf", {}, {}, colour)
    kp0 = surf_keypoints(grey)
    np.testing.assert_array_equal(kp.xy, kp0.xy)
    np.testing.assert_array_equal(kp.angle_rad, kp0.angle_rad)
    np.testing.assert_array_equal(g, surf_describe(grey, kp0))
    m, var, quant = _m_images_and_noise(rgb, **colour, pairs=_JOINT_M)
    c0 = block_snr_weight(m, var, kp0, radius_per_size=0.5, quant_var=quant)
    np.testing.assert_array_equal(c, c0)
    assert (c > 0).any() and (c == 0).any()
    for k, mk in enumerate(m):
        live = np.flatnonzero(c0[:, k] > 0)
        ref = surf_describe(mk, kp0.take(live), coarse=True)
        np.testing.assert_allclose(parts[live, k], ref, rtol=0, atol=1e-6)
        assert not np.delete(parts[:, k], live, axis=0).any()
    f = extract(rgb, "color-surf", reduce=False)
    assert f.descriptors.shape == (len(kp), 192)


def test_noise_estimates_equal_separate_measurements() -> None:
    lin = _scene(7).astype(np.float32) / 255.0
    floor, a, b = noise_estimates(lin, 1 / 255, 3.0)
    assert floor == noise_floor(lin, 1 / 255, 3.0)
    assert (a, b) == noise_model(lin, 1 / 255)


def test_channels_reject_bad_input() -> None:
    rgb = _scene()
    kp = surf_keypoints(detection_grey(rgb))
    m = np.zeros((2, 160, 200), np.float32)
    with pytest.raises(ValueError, match="live"):
        surf_describe_channels(m, kp, live=np.ones((len(kp), 3), bool))
    with pytest.raises(ValueError, match="images"):
        surf_describe_channels(m[0], kp)
    bad = m.copy()
    bad[1, 0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        surf_describe_channels(bad, kp)
