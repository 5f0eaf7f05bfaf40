"""Noise-weighted colour blocks of the joint colour descriptor (issue 17): the sensor noise
model measured in the image, its propagation into the m-images, the Wiener weights, and the
joint descriptor falling back to exactly the grey one where colour carries no signal."""

import cv2
import numpy as np
import pytest

from tests.vision.features_utils import textured_rgb
from vision.evaluation import evaluate_pair
from vision.features import extract
from vision.features.colour import colour_features
from vision.features.colour_input import noise_model
from vision.features.colour_joint import block_snr_weight, m_noise_variance, robust_m_images
from vision.features.types import Keypoints


def _poisson_gaussian(clean: np.ndarray, a: float, b: float, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    noisy = clean + rng.normal(size=clean.shape) * np.sqrt(a * clean + b)
    return noisy.astype(np.float32)


def test_noise_model_recovers_shot_and_read_noise():
    ramp = np.linspace(0.02, 0.9, 300, dtype=np.float32)
    clean = np.repeat(np.repeat(ramp[None, :, None], 300, 0), 3, 2)
    a, b = noise_model(_poisson_gaussian(clean, 1e-3, 2e-5), 1e-9)
    assert a == pytest.approx(1e-3, rel=0.15) and 0 <= b < 5e-5
    for level in (0.1, 0.5, 0.9):  # the fitted variance at every level
        assert a * level + b == pytest.approx(1e-3 * level + 2e-5, rel=0.15)
    a0, b0 = noise_model(_poisson_gaussian(clean, 0.0, 1e-4, seed=1), 1e-9)
    assert a0 < 1e-4 and b0 == pytest.approx(1e-4, rel=0.2)
    # Quantisation is counted: a noiseless 8-bit image still has one step^2 / 12.
    assert noise_model(np.rint(clean * 255) / 255, 1 / 255)[1] >= (1 / 255) ** 2 / 12


def test_m_image_variance_matches_the_measured_one():
    """First-order propagation of var(C) = a C + b through log(C1 + f) - log(C2 + f)."""
    clean = np.empty((200, 200, 3), np.float32)
    clean[:, :100] = (0.05, 0.08, 0.03)  # dark: noisy ratios
    clean[:, 100:] = (0.6, 0.5, 0.4)
    a, b, f = 5e-4, 1e-5, 0.005
    noisy = _poisson_gaussian(clean, a, b)
    m = robust_m_images(noisy, floor=f)
    var = m_noise_variance(clean, floor=f, shot=a, read=b)
    for k in range(3):
        for sl in (np.s_[:, :100], np.s_[:, 100:]):
            assert np.var(m[k][sl]) == pytest.approx(float(var[k][sl].mean()), rel=0.15)


def test_weights_are_zero_on_noise_and_near_one_at_colour_edges():
    rng = np.random.default_rng(2)
    lin = np.full((160, 160, 3), 0.3, np.float32)
    lin[:, 80:, 0] = 0.6  # a red edge at x = 80
    a, b = 1e-4, 1e-5
    noisy = lin + rng.normal(size=lin.shape).astype(np.float32) * np.sqrt(a * lin + b)
    m = robust_m_images(noisy, floor=1e-3, pairs=(0, 2))
    var = m_noise_variance(noisy, floor=1e-3, shot=a, read=b, pairs=(0, 2))
    xy = np.array([[40.0, 80.0], [80.0, 80.0]])
    kp = Keypoints(xy, np.full(2, 3.0), np.zeros(2), np.ones(2), np.zeros(2, np.int32))
    w = block_snr_weight(m, var, kp)
    assert w.shape == (2, 2) and w.dtype == np.float32
    assert w[0, 0] < 0.1 and w[0, 1] < 0.1  # flat colour, noise only
    assert w[1, 0] > 0.9  # M1 = log(R/G) sees the red edge
    assert w[1, 1] < 0.1  # M3 = log(G/B) does not


def test_joint_descriptor_is_exactly_grey_when_colour_has_no_signal():
    """A grey scene (R = G = B): every colour block weighs 0, the reduced joint descriptor is
    the SIFT descriptor followed by zeros, so its matches are those of SIFT."""
    grey_rgb = cv2.cvtColor(cv2.cvtColor(textured_rgb(3), cv2.COLOR_RGB2GRAY), cv2.COLOR_GRAY2RGB)
    f = colour_features(grey_rgb, max_features=150)
    s = extract(grey_rgb, "sift", max_features=150)
    assert f.dim == 160
    np.testing.assert_array_equal(f.descriptors[:, :128], s.descriptors)
    assert np.all(f.descriptors[:, 128:] == 0)
    H = np.eye(3)
    g2 = np.clip(grey_rgb.astype(np.int16) * 0.7, 0, 255).astype(np.uint8)
    ev_c = evaluate_pair(f, colour_features(g2, max_features=150), H)
    ev_g = evaluate_pair(s, extract(g2, "sift", max_features=150), H)
    assert ev_c.recall_at_01 == ev_g.recall_at_01 and ev_c.auc == ev_g.auc


def test_colour_weights_fade_as_the_scene_darkens():
    """The same colour scene at lower exposure, same keypoints: shot and read noise grow
    relative to the signal, so the colour blocks lose weight (the descriptor tends to the grey
    one) and the darkest exposure has hardly any left."""
    rng = np.random.default_rng(4)
    clean = textured_rgb(4).astype(np.float32) / 255.0
    kp = extract(textured_rgb(4), "sift", max_features=200).keypoints
    means = []
    for gain in (1.0, 0.1, 0.01):
        photons = rng.poisson(clean * gain * 4000.0) + rng.normal(0, 3.0, clean.shape)
        lin = np.clip(photons, 0, 4000).astype(np.float32) / 4000.0
        a, b = noise_model(lin, 1 / 4000)
        m = robust_m_images(lin, floor=3 * np.sqrt(b), pairs=(0, 2))
        var = m_noise_variance(lin, floor=3 * np.sqrt(b), shot=a, read=b, pairs=(0, 2))
        means.append(float(block_snr_weight(m, var, kp).mean()))
    assert means[0] > 0.5 and means[0] > means[1] > means[2] and means[2] < 0.1
