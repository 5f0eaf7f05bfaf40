"""The chapter's colour-invariant descriptor (equations 15-19): m-images, invariance to a
global per-channel gain, synthetic transforms, PCA, bad input."""

import cv2
import numpy as np
import pytest

from tests.vision.features_utils import match_quality, perspective, similarity, textured_rgb, warp
from vision.features import extract
from vision.features.colour import (
    EPS,
    colour_features,
    describe_colour_sift,
    m_images,
    m_images_uint8,
)
from vision.features.patches import detect_sift
from vision.features.pca import default_basis

GAIN = np.array([1.25, 0.8, 0.5])  # a strong colour cast: R up, G and B down


def _gained(img: np.ndarray, gain=GAIN) -> np.ndarray:
    return np.clip(np.rint(img * gain), 0, 255).astype(np.uint8)


def test_neighbour_differences_of_m_images_are_the_log_ratios_of_equation_15():
    img = textured_rgb(0, 64).astype(np.float64)
    m = m_images(img)
    r, g, b = (img[..., i] + EPS for i in range(3))
    # x1 = (row, col + 1), x2 = (row, col): log m1 = log(R1 G2 / (R2 G1))  (eqs. 15-17)
    log_m1 = np.log(r[:, 1:] * g[:, :-1] / (r[:, :-1] * g[:, 1:]))
    log_m3 = np.log(g[1:] * b[:-1] / (g[:-1] * b[1:]))  # vertical neighbours for m3
    np.testing.assert_allclose(m[0][:, 1:] - m[0][:, :-1], log_m1, atol=1e-5)
    np.testing.assert_allclose(m[2][1:] - m[2][:-1], log_m3, atol=1e-5)
    assert m.shape == (3, 64, 64) and m.dtype == np.float32
    np.testing.assert_allclose(np.median(m.reshape(3, -1), axis=1), 0, atol=1e-6)


def test_m_images_are_unchanged_by_a_global_per_channel_gain():
    img = textured_rgb(1)
    m0, m1 = m_images(img), m_images(_gained(img))
    # Exact up to uint8 rounding of the gained image and eps = 1 DN on values >= 10 DN.
    assert np.abs(m1 - m0).max() < 0.12
    assert np.abs(m1 - m0).mean() < 0.02


def test_uint8_mapping_is_the_documented_one():
    m = np.array([[-4.0, -1.0, 0.0, 0.5, 4.0]])
    np.testing.assert_array_equal(m_images_uint8(m), [[0, 88, 128, 148, 255]])


def test_colour_descriptor_is_invariant_to_gain_where_grey_sift_degrades():
    """Same keypoints in both images: the colour descriptors barely move under the colour
    cast, OpenCV SIFT on the grey image moves far more."""
    img = textured_rgb(3)
    _, cvk = detect_sift(cv2.cvtColor(img, cv2.COLOR_RGB2GRAY), max_features=200)
    c0, c1 = describe_colour_sift(img, cvk), describe_colour_sift(_gained(img), cvk)
    sift = cv2.SIFT_create()
    s0 = sift.compute(cv2.cvtColor(img, cv2.COLOR_RGB2GRAY), cvk)[1]
    s1 = sift.compute(cv2.cvtColor(_gained(img), cv2.COLOR_RGB2GRAY), cvk)[1]

    def rel(a, b):  # per-keypoint change relative to the descriptor norm
        return np.median(np.linalg.norm(a - b, axis=1) / np.linalg.norm(a, axis=1))

    assert rel(c0, c1) < 0.03  # measured 0.017
    assert rel(s0, s1) > 3 * rel(c0, c1)  # measured 0.081


def test_colour_matching_under_a_colour_cast():
    """Detected independently (keypoints on the grey images, which the cast changes), the
    colour descriptors still match."""
    img = textured_rgb(3)
    q = match_quality(extract(img, "color-sift"), extract(_gained(img), "color-sift"), np.eye(3))
    assert q["n_gt"] > 200 and q["accuracy"] > 0.85


@pytest.mark.parametrize(
    "H",
    [similarity(320, 30, 1.0), similarity(320, -15, 0.7), perspective(320)],
    ids=["rotation", "scale", "homography"],
)
def test_corresponding_points_match_under_known_transforms(H):
    img = textured_rgb(0)
    a, b = colour_features(img), colour_features(warp(img, H))
    assert a.dim == 160 and a.method == "color-sift"
    q = match_quality(a, b, H)
    assert q["n_gt"] > 100
    assert q["accuracy"] > 0.7 > 100 * q["chance"]
    assert q["pair_over_random"] < 0.6


def test_reduce_false_keeps_the_384_dims_and_pca_projects_the_colour_blocks():
    img = textured_rgb(5)
    full = colour_features(img, reduce=False, max_features=50)
    red = colour_features(img, max_features=50)
    b = default_basis("color-sift")
    assert full.dim == 384 and red.dim == 160 and red.version == b.version != full.version
    np.testing.assert_array_equal(red.descriptors[:, :128], full.descriptors[:, :128])
    np.testing.assert_allclose(
        red.descriptors[:, 128:], full.descriptors[:, 128:] @ b.components, atol=1e-4
    )
    np.testing.assert_array_equal(full.keypoints.xy, red.keypoints.xy)


def test_colour_surf_contract():
    pytest.importorskip("vision.features.surf")
    img = textured_rgb(0)
    full = extract(img, "color-surf", reduce=False, max_features=100)
    assert full.dim == 192 and full.method == "color-surf"
    H = similarity(320, 20, 0.9)
    q = match_quality(extract(img, "color-surf"), extract(warp(img, H), "color-surf"), H)
    assert q["accuracy"] > 0.5
    red = extract(img, "color-surf", max_features=100)
    assert red.dim == 80 and red.version == default_basis("color-surf").version


def test_bad_input_raises_value_error_naming_it():
    img = textured_rgb(0, 64)
    with pytest.raises(ValueError, match="base must be one of sift, surf, got 'orb'"):
        colour_features(img, base="orb")
    with pytest.raises(ValueError, match=r"uint8 \(H, W, 3\)"):
        colour_features(img[..., 0])
    with pytest.raises(ValueError, match="eps must be > 0, got 0"):
        m_images(img, eps=0)
    with pytest.raises(ValueError, match="upright"):
        colour_features(img, upright=True)
    with pytest.raises(ValueError, match="gives 256"):
        colour_features(img, basis=default_basis("gloh"))
