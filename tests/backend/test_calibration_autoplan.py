"""The automatic calibration's view planner (no simulator needed)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from backend.calibration.auto import AUTO_CRITERIA, nominal_camera
from backend.calibration.autoplan import NOMINAL_T_EE_CAM, board_box, plan_calibration_poses
from robot.collision import CollisionWorld
from robot.errors import Unreachable
from robot.kinematics import T_base_ee
from robot.model import ASEA
from robot.sim.obstacles import collision_world
from vision.calibration import Chessboard, coverage_map, rotation_diversity

BOARD = Chessboard(9, 6, 0.025)
# Face up on the simulated cell's table.
T_TABLE = np.array([[1.0, 0, 0, -0.12], [0, -1.0, 0, -0.75], [0, 0, -1.0, 0.452], [0, 0, 0, 1]])


@pytest.fixture(scope="module")
def plan():
    return plan_calibration_poses(
        T_TABLE, BOARD, nominal_camera(640, 480), world=collision_world(), n_poses=15, seed=4
    )


def test_views_are_reachable_free_and_show_the_board(plan):
    cam = nominal_camera(640, 480)
    world = collision_world().with_boxes(board_box(BOARD, T_TABLE))
    assert plan.n_primary == 15 and len(plan.views) > 15
    for v in plan.views:
        assert ASEA.within_limits(v.q).all()
        assert not world.collides(v.q)
        T = T_base_ee(v.q) @ NOMINAL_T_EE_CAM
        uv = cam.project_world(BOARD.object_points(), np.linalg.inv(T) @ T_TABLE)
        assert (uv >= 19).all() and (uv[:, 0] <= 620).all() and (uv[:, 1] <= 460).all()
        np.testing.assert_allclose(uv, v.corners_px)


def test_the_plan_meets_the_collection_criteria(plan):
    primary = plan.views[: plan.n_primary]
    cov = coverage_map([v.corners_px for v in primary], (640, 480))
    div = rotation_diversity(np.array([T_base_ee(v.q) for v in primary]))
    assert AUTO_CRITERIA.unmet(cov, div) == []
    assert set(plan.as_dict()["refused"]) == {"unreachable", "collision", "not_in_view"}


def test_same_seed_same_plan():
    a = plan_calibration_poses(
        T_TABLE, BOARD, nominal_camera(640, 480), n_poses=5, seed=1, n_candidates=300
    )
    b = plan_calibration_poses(
        T_TABLE, BOARD, nominal_camera(640, 480), n_poses=5, seed=1, n_candidates=300
    )
    assert all(np.array_equal(x.q, y.q) for x, y in zip(a.views, b.views, strict=True))


def test_board_out_of_reach_is_a_clear_error():
    far = T_TABLE.copy()
    far[:3, 3] = (2.8, 0.0, 0.45)
    with pytest.raises(Unreachable, match="cannot be calibrated from here: of 200 candidate"):
        plan_calibration_poses(far, BOARD, nominal_camera(640, 480), n_candidates=200)


def test_board_facing_away_is_refused():
    down = T_TABLE.copy()
    down[:3, :3] = np.diag([1.0, 1.0, 1.0])  # printed face towards the floor
    with pytest.raises(Unreachable, match="do not show"):
        plan_calibration_poses(
            down, BOARD, nominal_camera(640, 480), n_candidates=200, world=CollisionWorld()
        )


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"n_poses": 2}, "n_poses must be >= 3, got 2"),
        ({"distance_m": (0.5, 0.2)}, "distance_m must satisfy"),
        ({"n_reserve": -1}, "n_reserve must be >= 0"),
    ],
)
def test_bad_parameters(kwargs, message):
    with pytest.raises(ValueError, match=message):
        plan_calibration_poses(T_TABLE, BOARD, nominal_camera(640, 480), **kwargs)
    with pytest.raises(ValueError, match="T_base_board must be a finite 4x4"):
        plan_calibration_poses(np.eye(3), BOARD, nominal_camera(640, 480))


def test_nominal_camera():
    cam = nominal_camera(640, 480, fovy_deg=60.0)
    assert cam.K[1, 1] == pytest.approx(240.0 / math.tan(math.radians(30.0)))
    assert cam.K[0, 2] == 319.5
