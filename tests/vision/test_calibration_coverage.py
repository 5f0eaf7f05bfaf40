"""View-set criteria (coverage, rotation diversity) and view planning."""

import numpy as np
import pytest

from tests.utils.calibration import BOARD, TRUE_CAMERA, TRUE_T_BASE_BOARD, pose
from vision.calibration import (
    CoverageMap,
    ViewSetCriteria,
    candidate_camera_poses,
    coverage_map,
    look_at,
    plan_views,
    rotation_diversity,
)


def test_coverage_counts_corners_per_cell():
    pts = np.array(
        [[0.0, 0.0], [639.0, 479.0], [320.0, 240.0], [321.0, 241.0], [-5.0, 10.0], [np.nan, 3.0]]
    )
    cov = coverage_map([pts], (640, 480), grid=(4, 3))
    assert cov.counts.shape == (3, 4) and cov.counts.sum() == 4  # outside and NaN points dropped
    assert cov.counts[0, 0] == 1 and cov.counts[2, 3] == 1 and cov.counts[1, 2] == 2
    assert cov.fraction == pytest.approx(3 / 12) and cov.corner_cells == 2
    back = CoverageMap.from_dict(cov.as_dict())
    assert np.array_equal(back.counts, cov.counts) and back.image_size == (640, 480)
    with pytest.raises(ValueError, match=r"grid must be at least \(1, 1\), got \(0, 3\)"):
        coverage_map([pts], (640, 480), grid=(0, 3))


def _rot(rv_deg):
    return pose(rv_deg, (0, 0, 0))


def test_diversity_of_pure_translations_is_zero():
    d = rotation_diversity(np.array([pose((0, 0, 0), (x, 0, 0)) for x in range(5)]))
    assert (
        d.n_poses == 5
        and d.max_angle_deg == pytest.approx(0.0, abs=1e-9)
        and d.axis_spread_deg == 0.0
    )


def test_diversity_about_one_axis_has_no_axis_spread():
    d = rotation_diversity(np.array([_rot((0, 0, a)) for a in (0, 15, 30, 45)]))
    assert d.max_angle_deg == pytest.approx(45.0) and d.axis_spread_deg == pytest.approx(
        0.0, abs=1e-6
    )


def test_diversity_about_two_perpendicular_axes():
    d = rotation_diversity(np.array([_rot((0, 0, 0)), _rot((30, 0, 0)), _rot((0, 30, 0))]))
    # The pairs turn about x, about y and about a direction between them.
    assert d.axis_spread_deg > 60.0
    assert 40.0 < d.max_angle_deg < 45.0  # R_x(30)^T R_y(30) turns by 42.0 deg


def test_criteria_say_what_is_missing():
    cov = coverage_map([np.array([[10.0, 10.0]])], (640, 480))
    div = rotation_diversity(np.array([_rot((0, 0, 0)), _rot((0, 0, 10))]))
    unmet = ViewSetCriteria().unmet(cov, div)
    assert unmet == [
        "2 views, need 12",
        "corners cover 2% of the image, need 70%",
        "corners seen in 1 image corners, need 3",
        "largest rotation between views 10.0 deg, need 30",
        "rotation axes spread 0.0 deg, need 30",
    ]


def test_look_at_uses_opencv_camera_axes():
    T = look_at([0, 0, 1.0], [0, 0, 0])
    np.testing.assert_allclose(T[:3, 2], [0, 0, -1], atol=1e-12)  # +z towards the target
    np.testing.assert_allclose(T[:3, 3], [0, 0, 1.0])
    assert np.linalg.det(T[:3, :3]) == pytest.approx(1.0)
    with pytest.raises(ValueError, match="eye and target must differ"):
        look_at([1, 2, 3], [1, 2, 3])


def test_candidates_look_at_the_printed_side():
    C = candidate_camera_poses(TRUE_T_BASE_BOARD, BOARD, n=50, rng=np.random.default_rng(0))
    centre = TRUE_T_BASE_BOARD @ np.r_[BOARD.object_points().mean(axis=0), 1.0]
    for T in C:
        to_board = centre[:3] - T[:3, 3]
        dist = np.linalg.norm(to_board)
        assert 0.35 <= dist <= 0.6 + 1e-9
        assert np.dot(T[:3, 2], to_board / dist) > 0.99  # aims at the board (within jitter)
        # The camera is on the printed side: the board's +z points away from it (tilt up
        # to 40 deg, plus up to 5 deg of aim jitter).
        assert np.dot(TRUE_T_BASE_BOARD[:3, 2], T[:3, 2]) > np.cos(np.radians(46))


def test_plan_views_picks_diverse_views_that_see_the_whole_board():
    C = candidate_camera_poses(TRUE_T_BASE_BOARD, BOARD, n=150, rng=np.random.default_rng(1))
    plan = plan_views(TRUE_T_BASE_BOARD, BOARD, TRUE_CAMERA, C, n_views=12)
    assert len(plan.indices) == 12 and len(set(plan.indices)) == 12
    assert ViewSetCriteria(min_corner_cells=0).unmet(plan.coverage, plan.diversity) == []
    # A random pick of the same size is less diverse.
    rnd = rotation_diversity(C[:12])
    assert plan.diversity.median_angle_deg > rnd.median_angle_deg


def test_plan_views_honours_the_feasibility_predicate():
    C = candidate_camera_poses(TRUE_T_BASE_BOARD, BOARD, n=80, rng=np.random.default_rng(2))
    reach_x = float(np.median(C[:, 0, 3]))
    plan = plan_views(
        TRUE_T_BASE_BOARD, BOARD, TRUE_CAMERA, C, n_views=10, feasible=lambda T: T[0, 3] < reach_x
    )
    assert all(C[i, 0, 3] < reach_x for i in plan.indices)
    assert plan.skipped >= 40
