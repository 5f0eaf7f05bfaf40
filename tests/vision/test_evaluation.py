"""vision.evaluation: region overlap on hand-checkable shapes, recall / 1-precision (eqs. 24-25)
on constructed match sets, and SIFT on Oxford graf 1-2 against a floor."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from vision.evaluation import (
    curve_from_matches,
    ellipse_overlap_error,
    evaluate_pair,
    overlap_errors,
    project_regions,
)
from vision.features import Features, Keypoints, extract


def _circle(r: float) -> np.ndarray:
    return np.eye(2)[None] / r**2


@pytest.mark.parametrize("d", [0.0, 3.0, 6.0, 12.0, 19.0])
def test_overlap_of_two_equal_circles_matches_the_lens_area(d):
    r = 10.0
    lens = 2 * r**2 * math.acos(d / (2 * r)) - d / 2 * math.sqrt(4 * r**2 - d**2)
    want = 1.0 - lens / (2 * math.pi * r**2 - lens)
    got = ellipse_overlap_error(np.zeros((1, 2)), _circle(r), np.array([[d, 0.0]]), _circle(r))
    assert got[0] == pytest.approx(want, abs=0.015)


def test_overlap_of_disjoint_nested_and_crossed_ellipses():
    c = np.zeros((1, 2))
    assert ellipse_overlap_error(c, _circle(5), np.array([[11.0, 0]]), _circle(5))[0] == 1.0
    # Concentric circles: 1 - (r1 / r2)^2.
    got = ellipse_overlap_error(c, _circle(6), c, _circle(10))[0]
    assert got == pytest.approx(1 - 0.36, abs=0.015)
    # Ellipse with axes (a, b) and the same turned by 90 deg: intersection 4 a b atan(b / a).
    a, b = 12.0, 6.0
    e1 = np.diag([1 / a**2, 1 / b**2])[None]
    e2 = np.diag([1 / b**2, 1 / a**2])[None]
    inter = 4 * a * b * math.atan(b / a)
    want = 1 - inter / (2 * math.pi * a * b - inter)
    assert ellipse_overlap_error(c, e1, c, e2)[0] == pytest.approx(want, abs=0.015)


def test_projection_of_a_circle_by_an_affine_map_is_exact():
    A = np.array([[2.0, 0.0, 5.0], [0.0, 0.5, -3.0], [0.0, 0.0, 1.0]])
    c, M = project_regions(np.array([[10.0, 20.0]]), _circle(4.0), A)
    np.testing.assert_allclose(c, [[25.0, 7.0]])
    # Semi-axes 8 along x, 2 along y.
    np.testing.assert_allclose(M[0], np.diag([1 / 64, 1 / 4]), atol=1e-12)


def test_curve_from_a_constructed_match_set():
    score = np.array([0.1, 0.2, 0.3, 0.4, 0.5])
    correct = np.array([True, True, False, True, False])
    c = curve_from_matches(score, correct, 5)
    np.testing.assert_allclose(c.recall, [0.2, 0.4, 0.4, 0.6, 0.6])  # eq. 24
    np.testing.assert_allclose(c.one_minus_precision, [0, 0, 1 / 3, 1 / 4, 2 / 5])  # eq. 25
    assert c.best_recall == pytest.approx(0.6)
    assert c.recall_at(0.1) == pytest.approx(0.4)
    assert c.recall_at(0.25) == pytest.approx(0.6)
    # Envelope: 0.4 on [0, 0.25), 0.6 on [0.25, 1].
    assert c.auc == pytest.approx(0.4 * 0.25 + 0.6 * 0.75, abs=2e-3)


def test_curve_groups_equal_scores_into_one_threshold():
    c = curve_from_matches(np.array([1.0, 1.0, 2.0]), np.array([True, False, True]), 4)
    np.testing.assert_allclose(c.threshold, [1.0, 2.0])
    np.testing.assert_allclose(c.recall, [0.25, 0.5])


def _kp(xy: np.ndarray, size: float) -> Keypoints:
    n = len(xy)
    return Keypoints(xy, np.full(n, size), np.zeros(n), np.ones(n), np.zeros(n, np.int32))


def test_evaluate_pair_on_a_constructed_scene():
    # 10 regions on a grid; b is a shifted, 1.5x enlarged view. 8 descriptors repeat in b
    # (with slight noise), 2 are replaced by unrelated ones: recall 0.8 at no false match, and
    # the 2 unrelated nearest neighbours come last with high ratios.
    rng = np.random.default_rng(3)
    xy = np.array([[40.0 + 50 * (i % 5), 40.0 + 60 * (i // 5)] for i in range(10)])
    H = np.array([[1.5, 0, 10.0], [0, 1.5, 5.0], [0, 0, 1.0]])
    xy_b = xy * 1.5 + [10.0, 5.0]
    desc = rng.normal(size=(10, 16)).astype(np.float32)
    desc_b = desc + rng.normal(scale=0.01, size=desc.shape).astype(np.float32)
    desc_b[8:] = rng.normal(size=(2, 16)).astype(np.float32)
    a = Features(_kp(xy, 6.0), desc, "t", "1", False, (200, 300))
    b = Features(_kp(xy_b, 9.0), desc_b, "t", "1", False, (300, 450))
    ev = evaluate_pair(a, b, H)
    assert ev.n_correspondences == 10
    assert ev.best_recall == pytest.approx(0.8)
    assert ev.recall_at_01 == pytest.approx(0.8)
    assert ev.curve.one_minus_precision[-1] == pytest.approx(0.2)
    # Regions outside the other image do not count: crop b to its left half.
    b_half = Features(b.keypoints, b.descriptors, "t", "1", False, (300, 225))
    assert evaluate_pair(a, b_half, H).n_a == 6
    # Threshold strategy: every pair below a distance; the 8 good pairs are the closest.
    th = evaluate_pair(a, b, H, strategy="threshold")
    assert th.curve.recall_at(0.0) == pytest.approx(0.8)


def test_overlap_errors_reject_scale_mismatch_and_bad_input():
    a = _kp(np.array([[50.0, 50.0]]), 10.0)
    b = _kp(np.array([[50.0, 50.0], [50.0, 50.0]]), 10.0)
    b = Keypoints(b.xy, np.array([10.0, 30.0]), b.angle_rad, b.response, b.octave)
    ov = overlap_errors(a, b, np.eye(3))
    assert ov.index_b.tolist() == [0]  # 3x the size: overlap error 1 - 1/9
    with pytest.raises(ValueError, match="max_error"):
        overlap_errors(a, b, np.eye(3), max_error=1.5)
    with pytest.raises(ValueError, match="3x3"):
        overlap_errors(a, b, np.eye(2))
    f = Features(a, np.ones((1, 4), np.float32), "t", "1", False, (100, 100))
    with pytest.raises(ValueError, match="strategy"):
        evaluate_pair(f, f, np.eye(3), strategy="best")
    with pytest.raises(ValueError, match="invertible"):
        evaluate_pair(f, f, np.zeros((3, 3)))


def test_sift_on_oxford_graf_1_2_is_above_floor(data_dir):
    folder = data_dir / "registration" / "oxford" / "graf"
    if not (folder / "img1.png").is_file():
        pytest.skip(f"{folder} is absent (see the data README)")
    a = cv2.imread(str(folder / "img1.png"), cv2.IMREAD_GRAYSCALE)
    b = cv2.imread(str(folder / "img2.png"), cv2.IMREAD_GRAYSCALE)
    H = np.loadtxt(folder / "H1to2p")
    ev = evaluate_pair(
        extract(a, "sift", max_features=2000), extract(b, "sift", max_features=2000), H
    )
    # Measured 0.53 (OpenCV 4.14, 2000 features, regions normalised to 30 px); the floor
    # leaves room for other OpenCV versions.
    assert ev.recall_at_01 > 0.4
    assert ev.n_correspondences > 1000
