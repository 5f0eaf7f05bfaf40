"""Calibration against the simulator's ground truth (issue 7 targets).

One module-scoped set of rendered views (the simulated eye-in-hand camera with its default
sensor noise, arm at rest) is detected and calibrated once; the tests compare the solution
with ``engine.truth``, which the algorithms never see.  The views are chosen by the
auto-calibration planner; it is given the true camera only to choose where to put the arm
(as a person choosing good views would), never to the solvers.
"""

from __future__ import annotations

import numpy as np
import pytest

from backend.calibration.autoplan import plan_calibration_poses
from robot.kinematics import T_base_ee
from robot.sim.obstacles import collision_world
from vision.calibration import Chessboard, calibrate_hand_eye, calibrate_intrinsics
from vision.camera import PinholeCamera

pytestmark = pytest.mark.slow
N_VIEWS = 25


@pytest.fixture(scope="module")
def sim_views():
    from robot.sim import SimEngine
    from robot.sim.imaging import capture

    engine = SimEngine()
    try:
        T_board = np.array(
            [[1.0, 0, 0, -0.12], [0, -1.0, 0, -0.75], [0, 0, -1.0, 0.452], [0, 0, 0, 1.0]]
        )
        engine.place_board("chessboard", T_board)
        spec = engine.truth.board("chessboard").spec
        board = Chessboard(spec.cols, spec.rows, spec.square_m)
        truth = engine.truth.camera
        cam = PinholeCamera(truth.K, truth.dist, width=truth.width, height=truth.height)
        plan = plan_calibration_poses(
            T_board,
            board,
            cam,
            T_ee_cam=truth.T_ee_cam,
            world=collision_world(engine.config.layout),
            n_poses=N_VIEWS,
            n_reserve=0,
            margin_px=8.0,
            seed=3,
        )
        qs = [v.q for v in plan.views]
        images = [capture(engine, q).rgb for q in qs]
    finally:
        engine.stop()
    return {"board": board, "truth": truth, "q": qs, "images": images}


@pytest.fixture(scope="module")
def solved(sim_views):
    return calibrate_intrinsics(sim_views["images"], sim_views["board"])


def test_intrinsics_match_the_truth(sim_views, solved):
    intr = solved
    truth = sim_views["truth"]
    fx_err = abs(intr.K[0, 0] / truth.K[0, 0] - 1)
    fy_err = abs(intr.K[1, 1] / truth.K[1, 1] - 1)
    pp_err = float(np.hypot(*(intr.K[:2, 2] - truth.K[:2, 2])))
    print(f"fx {fx_err:.4%} fy {fy_err:.4%} pp {pp_err:.3f} px rms {intr.rms_px:.3f}")
    assert fx_err <= 0.002 and fy_err <= 0.002
    assert pp_err <= 1.0
    # Undistortion maps over the whole image, each model's own (what
    # cv2.initUndistortRectifyMap(K, dist, None, K) gives): where each pixel is sampled.
    true_cam = PinholeCamera(truth.K, truth.dist, width=truth.width, height=truth.height)
    mx_t, my_t = true_cam.undistort_maps(dtype=np.float64)
    mx, my = intr.camera.undistort_maps(dtype=np.float64)
    err = np.hypot(mx - mx_t, my - my_t)
    print(f"map error max {np.nanmax(err):.3f} px")
    assert np.nanmax(err) <= 0.3


def test_hand_eye_matches_the_truth(sim_views, solved):
    from vision.calibration import detect_pattern

    intr = solved
    board = sim_views["board"]
    dets = [detect_pattern(img, board) for img in sim_views["images"]]
    poses = np.array([T_base_ee(q) for q in sim_views["q"]])
    he = calibrate_hand_eye(dets, poses, board, intr.camera)
    T_true = sim_views["truth"].T_ee_cam
    dt_mm = 1e3 * float(np.linalg.norm(he.T_ee_cam[:3, 3] - T_true[:3, 3]))
    R = he.T_ee_cam[:3, :3].T @ T_true[:3, :3]
    dr_deg = float(np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1))))
    print(f"hand-eye {dt_mm:.3f} mm {dr_deg:.4f} deg")
    assert dt_mm <= 1.0 and dr_deg <= 0.1
