"""PCA-SIFT (Ke and Sukthankar 2004): analytic reference on a ramp, synthetic transforms
with ground truth, the basis and version, bad input."""

import cv2
import numpy as np
import pytest

from tests.vision.features_utils import match_quality, perspective, similarity, textured_rgb, warp
from vision.features import Keypoints, extract
from vision.features.pca import PcaBasis, default_basis
from vision.features.pcasift import pca_sift_features, pca_sift_raw


def _kp(x, y, size, angle):
    return Keypoints(np.array([[x, y]]), [size], [angle], [1.0], [0])


def _ramp(size=200):
    return np.tile(100 + 0.5 * np.arange(size, dtype=np.float32), (size, 1))


def test_raw_vector_of_a_ramp_is_the_analytic_one():
    """I = 100 + 0.5 x: at orientation 0 every horizontal gradient is equal and the vertical
    ones vanish, so the unit vector is [1/39] * 1521 + [0] * 1521; turning the keypoint by
    90 deg counter-clockwise puts the ramp into the patch's vertical gradients."""
    v = pca_sift_raw(_ramp(), _kp(100, 100, 20, 0.0))[0]
    assert v.shape == (3042,)
    np.testing.assert_allclose(v[:1521], 1 / 39, atol=1e-5)
    np.testing.assert_allclose(v[1521:], 0, atol=1e-5)
    w = pca_sift_raw(_ramp(), _kp(100, 100, 20, np.pi / 2))[0]
    np.testing.assert_allclose(w[:1521], 0, atol=1e-5)
    np.testing.assert_allclose(w[1521:], 1 / 39, atol=1e-5)


def test_patch_scale_follows_keypoint_size():
    """A disc of radius 15 px seen by keypoints of size 10 and 20 (sample steps 1.5 and
    3 px): its edge lies 10 and 5 samples from the patch centre."""
    img = np.zeros((200, 200), np.float32)
    cv2.circle(img, (100, 100), 15, 255.0, -1, lineType=cv2.LINE_AA)
    img = cv2.GaussianBlur(img, (0, 0), 1.0)
    from vision.features.patches import sample_patches

    p = sample_patches(
        img,
        Keypoints(np.array([[100, 100], [100, 100.0]]), [10, 20], [0, 0], [1, 1], [0, 0]),
        size=41,
        step_per_size=0.15,
    )
    radius = [(q[20, 21:] > 127).sum() for q in p]  # samples right of the centre in the disc
    assert radius[0] == pytest.approx(10, abs=1)
    assert radius[1] == pytest.approx(5, abs=1)


@pytest.mark.parametrize(
    "H",
    [similarity(320, 30, 1.0), similarity(320, -15, 0.7), perspective(320)],
    ids=["rotation", "scale", "homography"],
)
def test_corresponding_points_match_under_known_transforms(H):
    img = cv2.cvtColor(textured_rgb(0), cv2.COLOR_RGB2GRAY)
    a, b = (
        pca_sift_features(img),
        pca_sift_features(cv2.cvtColor(warp(textured_rgb(0), H), cv2.COLOR_RGB2GRAY)),
    )
    assert a.dim == 36
    q = match_quality(a, b, H)
    assert q["n_gt"] > 100
    assert q["accuracy"] > 0.7 > 100 * q["chance"]
    assert q["pair_over_random"] < 0.6


def test_extract_routes_and_version_follows_basis():
    img = textured_rgb(2)
    f = extract(img, "pca-sift", max_features=80)
    assert f.method == "pca-sift" and f.dim == 36 and len(f) == 80
    assert f.version == default_basis("pca-sift").version
    raw = pca_sift_features(cv2.cvtColor(img, cv2.COLOR_RGB2GRAY), max_features=80, reduce=False)
    assert raw.dim == 3042 and raw.version != f.version
    np.testing.assert_allclose(np.linalg.norm(raw.descriptors, axis=1), 1, atol=1e-5)
    # Another basis gives another version (stored descriptors are not comparable).
    b = default_basis("pca-sift")
    other = PcaBasis(b.mean + 1e-3, b.components, b.eigenvalues, "pca-sift")
    g = extract(img, "pca-sift", max_features=80, basis=other)
    assert g.version != f.version
    np.testing.assert_allclose(g.descriptors, other.project(raw.descriptors), atol=1e-5)


def test_bad_input_raises_value_error_naming_it():
    img = cv2.cvtColor(textured_rgb(0, 64), cv2.COLOR_RGB2GRAY)
    with pytest.raises(ValueError, match="threshold must be > 0, got -1"):
        pca_sift_features(img, threshold=-1)
    with pytest.raises(ValueError, match="max_features must be >= 1, got 0"):
        pca_sift_features(img, max_features=0)
    with pytest.raises(ValueError, match="3042"):
        pca_sift_features(img, basis=default_basis("gloh"))
