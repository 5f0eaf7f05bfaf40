"""The colour descriptor's options for real cameras (issue 17): the joint layout, uint16 linear
input, sRGB linearisation, the noise floor, the clipping mask, contrast-weighted blocks, the
OpponentSIFT baseline and the validation of bad options."""

import cv2
import numpy as np
import pytest

from tests.vision.features_utils import textured_rgb
from vision.features import extract
from vision.features.colour import colour_features, describe_colour_sift, detection_grey
from vision.features.colour_input import (
    clipped_weight,
    linear_from_image,
    noise_sigma,
    srgb8_from_linear,
    srgb_decode,
    srgb_encode,
)
from vision.features.colour_joint import block_snr_weight, joint_m_images, robust_m_images
from vision.features.opponent import opponent_channels
from vision.features.patches import detect_sift
from vision.features.pca import default_basis

WHITE16 = 4000.0  # a 12-bit-like sensor inside a 16-bit file


def _linear16(seed: int = 0, gain=(1.0, 1.0, 1.0)) -> np.ndarray:
    """A textured image as 16-bit linear values up to about WHITE16, times a per-channel gain."""
    lin = srgb_decode(textured_rgb(seed).astype(np.float32) / 255.0)
    v = lin * WHITE16 * np.asarray(gain, np.float32)
    return np.clip(np.rint(v), 0, 65535).astype(np.uint16)


def test_joint_layout_shapes_versions_and_the_grey_block_is_sift():
    img = textured_rgb(0)
    full = colour_features(img, reduce=False, max_features=150)
    red = colour_features(img, max_features=150)
    sift = extract(img, "sift", max_features=150)
    assert full.dim == 384 and full.descriptors.dtype == np.float32
    assert full.version == "color-sift-joint-raw-1"
    basis = default_basis("color-sift")
    assert red.dim == 128 + basis.dim_out == 160 and red.version == basis.version
    # Same keypoints as the grey base, and the first block is its descriptor, in both.
    np.testing.assert_array_equal(full.keypoints.xy, sift.keypoints.xy)
    np.testing.assert_array_equal(full.descriptors[:, :128], sift.descriptors)
    np.testing.assert_array_equal(red.descriptors[:, :128], sift.descriptors)
    # The colour blocks are projected on the basis without its mean shift (0 stays 0).
    np.testing.assert_allclose(
        red.descriptors[:, 128:], full.descriptors[:, 128:] @ basis.components, atol=1e-3
    )


def test_chapter_layout_is_the_descriptor_of_issue_6():
    img = textured_rgb(1)
    ch = colour_features(img, layout="chapter", reduce=False, max_features=80)
    _, cvk = detect_sift(cv2.cvtColor(img, cv2.COLOR_RGB2GRAY), max_features=80)
    np.testing.assert_array_equal(ch.descriptors, describe_colour_sift(img, cvk))
    red = colour_features(img, layout="chapter", max_features=80)
    assert red.version == default_basis("color-sift-chapter").version


def test_colour_surf_joint_shapes():
    pytest.importorskip("vision.features.surf")
    img = textured_rgb(2)
    full = extract(img, "color-surf", reduce=False, max_features=100)
    surf = extract(img, "surf", max_features=100)
    assert full.dim == 192 and full.version == "color-surf-joint-raw-1"
    np.testing.assert_allclose(full.descriptors[:, :64], surf.descriptors, atol=1e-6)
    assert extract(img, "color-surf", max_features=100).dim == 64 + 16


def test_uint16_linear_input_detects_on_its_srgb_encoding():
    img16 = _linear16(3)
    f = extract(img16, "color-sift", white_level=WHITE16, max_features=120)
    assert f.descriptors.dtype == np.float32 and f.dim == 160 and f.image_shape == (320, 320)
    grey8 = srgb8_from_linear(img16, white_level=WHITE16)
    assert grey8.dtype == np.uint8
    np.testing.assert_array_equal(
        detection_grey(img16, white_level=WHITE16), cv2.cvtColor(grey8, cv2.COLOR_RGB2GRAY)
    )
    s = extract(grey8, "sift", max_features=120)
    np.testing.assert_array_equal(f.keypoints.xy, s.keypoints.xy)
    with pytest.raises(ValueError, match="uint16 linear RGB only for the colour methods"):
        extract(img16, "sift")


def test_linear_m_images_ignore_a_per_channel_gain_of_16_bit_values():
    a = joint_m_images(_linear16(4), white_level=WHITE16)
    b = joint_m_images(_linear16(4, gain=(0.6, 1.0, 1.4)), white_level=WHITE16)
    assert a.shape == (3, 320, 320) and a.dtype == np.float32
    assert np.abs(a - b).mean() < 0.01


def test_srgb_transfer_recovers_the_linear_colour_ratios_of_a_gamma_camera():
    """8-bit sRGB of linear light: linearised, its m-images are those of the linear values
    (up to 8-bit quantisation); read as they are, the log ratios are compressed about 2.4x
    (the curve's exponent) and bent near black."""
    lin = _linear16(5).astype(np.float32) / WHITE16
    a = np.rint(255 * srgb_encode(lin)).astype(np.uint8)
    ok = lin.min(axis=2) > 0.05
    truth = robust_m_images(lin, floor=1e-6)
    dec = joint_m_images(a, transfer="srgb", saturation=1.0, noise_floor=0.0)
    raw = joint_m_images(a, saturation=1.0, noise_floor=0.0)
    err_dec = np.abs(dec - truth)[:, ok].mean()
    err_raw = np.abs(raw - truth)[:, ok].mean()
    assert err_dec < 0.02 and err_raw > 5 * err_dec
    spread = np.std(truth[:, ok], axis=1) / np.std(raw[:, ok], axis=1)
    assert np.all((spread > 1.8) & (spread < 2.6))
    np.testing.assert_allclose(srgb_decode(srgb_encode(lin)), lin, atol=1e-5)


def test_noise_floor_flattens_dark_pixels_and_sigma_is_measured():
    rng = np.random.default_rng(0)
    noise = rng.normal(0.5, 0.02, size=(200, 200, 3)).astype(np.float32)
    assert noise_sigma(noise) == pytest.approx(0.02, rel=0.1)
    lin = np.full((64, 64, 3), 0.5, np.float32)
    lin[:, :32] = rng.uniform(0.0, 0.002, size=(64, 32, 3))  # dark and noisy
    lin[:, 32:, 0] = 0.3  # a real colour
    low = robust_m_images(lin, floor=1e-6)
    high = robust_m_images(lin, floor=0.02)
    assert np.abs(np.diff(low[0][:, :30], axis=1)).mean() > 0.3  # log ratios of noise swing
    assert np.abs(np.diff(high[0][:, :30], axis=1)).mean() < 0.05  # the floor damps them
    assert np.ptp(high[0][:, 34:]) < 1e-5  # a bright uniform colour stays uniform


def test_clipped_pixels_and_their_neighbours_are_neutral():
    lin = linear_from_image(textured_rgb(6))
    lin[100:110, 100:110, 1] = 1.0  # green clips
    w = clipped_weight(lin, 0.98)
    assert w.dtype == np.float32 and w.shape == (320, 320)
    assert w[99:111, 99:111].max() == 0 and w[97, 97] == 1
    m = robust_m_images(lin, floor=1e-3, weight=w)
    assert np.all(m[:, 99:111, 99:111] == 0)


def test_colour_blocks_vanish_on_a_grey_image():
    grey = cv2.cvtColor(cv2.cvtColor(textured_rgb(7), cv2.COLOR_RGB2GRAY), cv2.COLOR_GRAY2RGB)
    full = colour_features(grey, reduce=False, max_features=100, colour_weight=1.0)
    assert np.abs(full.descriptors[:, 128:]).max() < 1e-6
    m = joint_m_images(textured_rgb(7), pairs=(0, 2))
    c = block_snr_weight(m, np.full_like(m, 1e-4), full.keypoints)
    assert c.shape == (len(full), 2) and np.all((c >= 0) & (c < 1)) and c.max() > 0.5


def test_opponent_sift_baseline():
    img = textured_rgb(8)
    f = extract(img, "opponent-sift", max_features=100)
    s = extract(img, "sift", max_features=100)
    assert f.dim == 384 and f.method == "opponent-sift" and f.descriptors.dtype == np.float32
    np.testing.assert_array_equal(f.keypoints.xy, s.keypoints.xy)
    o = opponent_channels(np.array([[[200, 100, 50]]], np.uint8))
    np.testing.assert_array_equal(o[:, 0, 0], [178, 178, 117])  # (R-G)/2+127.5, ..., mean
    with pytest.raises(ValueError, match="needs an RGB image"):
        extract(img[..., 0], "opponent-sift")


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"layout": "grid"}, "layout must be one of joint, chapter, got 'grid'"),
        ({"transfer": "gamma"}, "transfer must be one of linear, srgb, got 'gamma'"),
        ({"noise_floor": -1.0}, r"noise_floor must be in \[0, 100\], got -1.0"),
        ({"noise_floor": True}, "noise_floor must be a number, got True"),
        ({"noise_floor": float("nan")}, "noise_floor must be in"),
        ({"saturation": 0.2}, r"saturation must be in \[0.5, 1\], got 0.2"),
        ({"colour_weight": 11}, r"colour_weight must be in \[0, 10\], got 11"),
        ({"white_level": 0}, r"white_level must be in \[1, 255\] for uint8, got 0"),
        ({"white_level": 300.0}, r"white_level must be in \[1, 255\]"),
        ({"white_level": "255"}, "white_level must be a number, got '255'"),
        ({"layout": "chapter", "transfer": "srgb"}, "layout 'chapter' reads the values as given"),
    ],
)
def test_bad_options_raise_value_error_quoting_them(options, message):
    with pytest.raises(ValueError, match=message):
        colour_features(textured_rgb(0, 64), **options)


def test_bad_images_raise_value_error():
    with pytest.raises(ValueError, match=r"uint8 \(H, W, 3\)"):
        colour_features(textured_rgb(0, 64).astype(np.float32))
    with pytest.raises(ValueError, match="white_level must be in"):
        colour_features(_linear16(0)[:64, :64], white_level=70000.0)
    with pytest.raises(ValueError, match="must be uint8 or uint16"):
        srgb8_from_linear(np.zeros((4, 4, 3), np.float32))
