"""GLOH (Mikolajczyk and Schmid 2005): the log-polar layout, analytic reference on a ramp,
synthetic transforms with ground truth, bad input."""

import cv2
import numpy as np
import pytest

from tests.vision.features_utils import match_quality, perspective, similarity, textured_rgb, warp
from vision.features import Keypoints, extract
from vision.features.gloh import GLOH_DIM, N_ORI, gloh_features, gloh_raw
from vision.features.pca import default_basis


def _kp(x, y, size, angle):
    return Keypoints(np.array([[x, y]]), [size], [angle], [1.0], [0])


def _ramp(size=200):
    return np.tile(100 + 0.5 * np.arange(size, dtype=np.float32), (size, 1))


@pytest.mark.parametrize(("angle", "bin_"), [(0.0, 0), (np.pi / 2, 12), (-np.pi / 4, 2)])
def test_ramp_fills_one_orientation_bin_in_all_17_locations(angle, bin_):
    """A ramp rising along +x has gradient direction 0; seen from a keypoint turned by
    ``angle`` (counter-clockwise) it points at ``-angle``: bin ``-angle / (2 pi / 16)``."""
    h = gloh_raw(_ramp(), _kp(100, 100, 20, angle))[0].reshape(17, N_ORI)
    assert GLOH_DIM == 272
    assert h[:, bin_].sum() > 0.999 * h.sum()
    assert np.all(h[:, bin_] > 0)  # every location bin sees gradients
    assert np.linalg.norm(h) == pytest.approx(1.0, abs=1e-5)


def test_location_bins_follow_the_log_polar_grid():
    """A step edge only on the keypoint's right (x > centre + 14 samples * step) reaches the
    outer ring only, in the sectors around angle 0 (sectors 0 and 7: bins 9 and 16; the blurred edge
    spills a little into sectors 1 and 6)."""
    img = np.zeros((200, 200), np.float32)
    step = 0.2 * 20  # STEP_PER_SIZE * size: 4 px per sample
    img[:, int(100 + 14 * step) :] = 200.0
    img = cv2.GaussianBlur(img, (0, 0), 1.5)
    h = gloh_raw(img, _kp(100, 100, 20, 0.0))[0].reshape(17, N_ORI)
    per_loc = h.sum(axis=1)
    assert per_loc[:9].sum() < 1e-3 * per_loc.sum()
    assert per_loc[[9, 16]].sum() > 0.85 * per_loc.sum()
    assert per_loc[[9, 10, 15, 16]].sum() > 0.999 * per_loc.sum()


@pytest.mark.parametrize(
    "H",
    [similarity(320, 30, 1.0), similarity(320, -15, 0.7), perspective(320)],
    ids=["rotation", "scale", "homography"],
)
def test_corresponding_points_match_under_known_transforms(H):
    img = textured_rgb(0)
    grey = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
    a = gloh_features(grey)
    b = gloh_features(cv2.cvtColor(warp(img, H), cv2.COLOR_RGB2GRAY))
    assert a.dim == 128
    q = match_quality(a, b, H)
    assert q["n_gt"] > 100
    assert q["accuracy"] > 0.7 > 100 * q["chance"]
    assert q["pair_over_random"] < 0.6


def test_extract_routes_reduce_option_and_version():
    img = textured_rgb(4)
    f = extract(img, "gloh", max_features=60)
    assert f.method == "gloh" and f.dim == 128 and len(f) == 60
    assert f.version == default_basis("gloh").version
    raw = extract(img, "gloh", max_features=60, reduce=False)
    assert raw.dim == 272 and raw.version != f.version
    assert np.all(raw.descriptors >= 0) and raw.descriptors.max() <= 0.2 / 0.2  # clipped, renormed
    np.testing.assert_allclose(
        f.descriptors, default_basis("gloh").project(raw.descriptors), atol=1e-5
    )


def test_bad_input_raises_value_error_naming_it():
    img = cv2.cvtColor(textured_rgb(0, 64), cv2.COLOR_RGB2GRAY)
    with pytest.raises(ValueError, match="threshold must be > 0, got 0"):
        gloh_features(img, threshold=0)
    with pytest.raises(ValueError, match="272"):
        gloh_features(img, basis=default_basis("color-sift"))
    assert gloh_raw(img, Keypoints.empty()).shape == (0, 272)
