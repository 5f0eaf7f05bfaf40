"""The eye-in-hand camera: rendered projections land where K, dist and the true pose say."""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np
import pytest

from robot.sim import CameraSpec, Lens, SimConfig, SimEngine
from robot.sim.camera import Sensor, exposure_end_poses, motion_blur
from robot.sim.imaging import Imager, capture
from robot.sim.poses import standard_configurations
from vision.camera import PinholeCamera

CONFIGS = standard_configurations()
# Views of the table that put the board in the middle and towards the image's edges.
OFFSETS = [
    (0.0, 0.0, 0.0, 0.0, 0.0),
    (0.15, 0.0, 0.0, 0.0, 0.0),
    (-0.12, 0.0, 0.0, 0.08, 0.0),
    (0.0, 0.0, 0.0, 0.12, 0.6),
    (0.05, 0.04, -0.04, -0.1, -0.4),
]


def _board_on_table(tilt_deg: float = 0.0) -> np.ndarray:
    """Board face up on the table (z_board down), optionally tilted about its x axis."""
    a = math.radians(tilt_deg)
    Rx = np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])
    T = np.eye(4)
    T[:3, :3] = np.diag([1.0, -1.0, -1.0]) @ Rx
    T[:3, 3] = (-0.1, -0.72, 0.452 + 0.22 * math.sin(abs(a)))  # propped up, clear of the table
    return T


def _render(engine: SimEngine, q, spec: CameraSpec | None = None) -> np.ndarray:
    return capture(engine, q, spec=spec or engine.config.camera.with_(noise_std_dn=0.0)).rgb


def _chessboard_errors(engine: SimEngine, q, board) -> np.ndarray:
    rgb = _render(engine, q)
    grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    ok, corners = cv2.findChessboardCorners(grey, (board.spec.cols, board.spec.rows))
    assert ok, f"chessboard not found from {np.degrees(q).round(1).tolist()}"
    corners = cv2.cornerSubPix(
        grey,
        corners,
        (5, 5),
        (-1, -1),
        (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-4),
    ).reshape(-1, 2)
    cam = engine.truth.camera
    pred = PinholeCamera(cam.K, cam.dist).project_world(
        board.corners_base, np.linalg.inv(engine.truth.T_base_cam(q))
    )
    # Detection order may start at either end: pair each corner with its prediction.
    d = np.linalg.norm(corners[:, None] - pred[None], axis=2)
    assert len(set(d.argmin(axis=1))) == len(pred)
    return d.min(axis=1)


@pytest.mark.parametrize("offset", OFFSETS)
def test_chessboard_corners_land_where_K_dist_and_pose_predict(engine, offset):
    board = engine.place_board("chessboard", _board_on_table())
    try:
        err = _chessboard_errors(engine, CONFIGS["table"] + np.array(offset), board)
    finally:
        engine.remove_board("chessboard")
    assert err.max() <= 0.5
    assert err.mean() <= 0.2


def test_tilted_charuco_corners_land_where_predicted(engine):
    board = engine.place_board("charuco", _board_on_table(tilt_deg=25.0))
    try:
        q = CONFIGS["table"]
        grey = cv2.cvtColor(_render(engine, q), cv2.COLOR_RGB2GRAY)
        det = cv2.aruco.CharucoDetector(board.spec.opencv_board())
        corners, ids, _, _ = det.detectBoard(grey)
    finally:
        engine.remove_board("charuco")
    assert ids is not None and len(ids) >= 30
    cam = engine.truth.camera
    pred = PinholeCamera(cam.K, cam.dist).project_world(
        board.corners_base[ids.ravel()], np.linalg.inv(engine.truth.T_base_cam(q))
    )
    err = np.linalg.norm(corners.reshape(-1, 2) - pred, axis=1)
    assert err.max() <= 0.5
    assert err.mean() <= 0.2


def test_ideal_lens_projects_without_distortion():
    spec = CameraSpec(dist=(0.0, 0.0, 0.0, 0.0, 0.0))
    e = SimEngine(SimConfig(camera=spec))
    try:
        board = e.place_board("chessboard", _board_on_table())
        err = _chessboard_errors(e, CONFIGS["table"] + np.array(OFFSETS[1]), board)
        assert err.max() <= 0.5
    finally:
        e.stop()


def test_intrinsics_come_from_the_vertical_field_of_view():
    spec = CameraSpec(fovy_deg=58.0)
    f = 240.0 / math.tan(math.radians(29.0))
    np.testing.assert_allclose(spec.K, [[f, 0, 319.5], [0, f, 239.5], [0, 0, 1]])
    assert spec.pinhole.fov_deg()[1] == pytest.approx(58.0, abs=1e-9)
    with pytest.raises(ValueError, match="fovy_deg"):
        CameraSpec(fovy_deg=1.0)
    with pytest.raises(ValueError, match="dist"):
        CameraSpec(dist=(0.1, 0.2, 0.3))


def test_lens_canvas_covers_every_distorted_pixel():
    for dist in [(-0.12, 0.03, 0.0008, -0.0005, 0.0), (0.1, -0.02, 0.0, 0.0, 0.0), (0.0,) * 5]:
        spec = CameraSpec(dist=dist)
        lens = Lens(spec)
        mx, my = spec.pinhole.distort_maps(lens.K_ideal)
        assert mx.min() >= 0 and my.min() >= 0
        assert mx.max() <= lens.ideal_width - 1 and my.max() <= lens.ideal_height - 1
        # The ideal canvas has the camera's focal length and a centred principal point.
        assert lens.K_ideal[0, 0] == pytest.approx(spec.focal_px)
        assert lens.K_ideal[0, 2] == pytest.approx((lens.ideal_width - 1) / 2)
        # A point seen by the ideal canvas at pixel p appears where the camera projects it.
        pts = np.array([[0.1, -0.05, 1.0], [-0.3, 0.2, 1.0], [0.45, 0.3, 1.0]])
        uv = spec.pinhole.project(pts)
        src = np.stack(
            [
                mx[np.round(uv[:, 1]).astype(int), np.round(uv[:, 0]).astype(int)],
                my[np.round(uv[:, 1]).astype(int), np.round(uv[:, 0]).astype(int)],
            ],
            axis=1,
        )
        ideal = PinholeCamera(
            lens.K_ideal, None, width=lens.ideal_width, height=lens.ideal_height
        ).project(pts)
        # Sampling at the rounded pixel moves the source by at most ~0.75 px.
        assert np.abs(src - ideal).max() < 1.0


def test_sensor_gain_exposure_and_seeded_noise():
    spec = CameraSpec(noise_std_dn=2.0)
    flat = np.full((480, 640, 3), 100, np.uint8)
    a = Sensor(spec).apply(flat, spec)
    b = Sensor(spec).apply(flat, spec)
    np.testing.assert_array_equal(a, b)  # same seed, same noise
    expected = math.sqrt(2.0**2 + 0.02 * 100)
    assert a.astype(float).std() == pytest.approx(expected, rel=0.05)
    assert a.astype(float).mean() == pytest.approx(100.0, abs=0.1)
    s2 = Sensor(spec)
    first, second = s2.apply(flat, spec), s2.apply(flat, spec)
    assert not np.array_equal(first, second)  # noise changes from frame to frame
    dark = spec.with_(noise_std_dn=0.0, exposure_s=0.004)
    assert Sensor(dark).apply(flat, dark).mean() == pytest.approx(50.0, abs=0.6)
    bright = spec.with_(noise_std_dn=0.0, gain=4.0)
    assert Sensor(bright).apply(flat, bright).max() == 255  # saturates


def test_motion_blur_follows_the_arm_speed():
    spec = CameraSpec(exposure_s=0.01)
    lens = Lens(spec)
    rng = np.random.default_rng(0)
    img = (rng.random((lens.ideal_height, lens.ideal_width, 3)) * 255).astype(np.uint8)
    depth = np.full((lens.ideal_height, lens.ideal_width), 0.5, np.float32)
    q = CONFIGS["top"]
    still = motion_blur(img, depth, lens.K_ideal, *exposure_end_poses(spec, q, np.zeros(5)))
    assert still is img
    # Turning the base at 0.5 rad/s sweeps the image sideways during 10 ms.
    fast = motion_blur(img, depth, lens.K_ideal, *exposure_end_poses(spec, q, [0.5, 0, 0, 0, 0]))
    slow = motion_blur(img, depth, lens.K_ideal, *exposure_end_poses(spec, q, [0.12, 0, 0, 0, 0]))

    def sharpness(a):
        return float(np.abs(np.diff(a.astype(float), axis=1)).mean())

    assert sharpness(fast) < 0.5 * sharpness(img)
    assert sharpness(fast) < sharpness(slow) < sharpness(img)


def test_camera_geometry_cannot_change_at_run_time(engine):
    imager = Imager(engine.config.camera)
    imager.set_sensor(engine.config.camera.with_(gain=2.0, noise_std_dn=0.0))
    with pytest.raises(ValueError, match="fovy_deg"):
        imager.set_sensor(engine.config.camera.with_(fovy_deg=40.0))
    with pytest.raises(ValueError, match="mounting"):
        imager.set_sensor(dataclasses.replace(engine.config.camera, T_ee_cam=np.eye(4)))
