"""PinholeCamera against OpenCV on random inputs (eqs. 1-5), to 1e-9."""

import cv2
import numpy as np
import pytest

from vision.camera import PinholeCamera, T_from_rvec_tvec, rotation_from_rvec

TIGHT = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 1000, 1e-16)


def _random_camera(rng: np.random.Generator, n_dist: int) -> PinholeCamera:
    fx, fy = rng.uniform(300, 900, size=2)
    cx, cy = rng.uniform(280, 360), rng.uniform(200, 280)
    K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    k = [rng.uniform(-0.3, 0.1), rng.uniform(-0.05, 0.1)]
    if n_dist >= 4:
        k += list(rng.uniform(-2e-3, 2e-3, size=2))
    if n_dist == 5:
        k.append(rng.uniform(-0.02, 0.02))
    return PinholeCamera(K, k, width=640, height=480)


def _cv_dist(cam: PinholeCamera) -> np.ndarray:
    return np.asarray(cam.dist, dtype=np.float64)


@pytest.mark.parametrize("n_dist", [0, 2, 4, 5])
@pytest.mark.parametrize("seed", range(4))
def test_project_world_matches_projectPoints_with_rvec_tvec(n_dist, seed):
    rng = np.random.default_rng(100 * n_dist + seed)
    cam = _random_camera(rng, n_dist) if n_dist else PinholeCamera(np.diag([500.0, 510.0, 1.0]))
    rvec = rng.normal(size=3) * rng.uniform(0.1, 2.5)
    tvec = rng.uniform([-0.2, -0.2, 2.0], [0.2, 0.2, 3.0])
    T = T_from_rvec_tvec(rvec, tvec)
    # World points inside a ball that stays in front of the camera and within the image.
    P_cam = rng.uniform([-0.6, -0.45, 1.2], [0.6, 0.45, 2.5], size=(1500, 3))
    P_world = (P_cam - T[:3, 3]) @ T[:3, :3]
    ref, _ = cv2.projectPoints(P_world, rvec, tvec, cam.K, _cv_dist(cam))
    np.testing.assert_allclose(cam.project_world(P_world, T), ref[:, 0], rtol=0, atol=1e-9)


def test_rotation_from_rvec_matches_cv2_rodrigues():
    rng = np.random.default_rng(7)
    for rvec in [*rng.normal(size=(50, 3)) * 2.0, np.zeros(3), np.array([1e-14, 0.0, 0.0])]:
        R_ref, _ = cv2.Rodrigues(rvec)
        np.testing.assert_allclose(rotation_from_rvec(rvec), R_ref, atol=1e-12)


@pytest.mark.parametrize("n_dist", [2, 4, 5])
@pytest.mark.parametrize("seed", range(3))
def test_undistort_pixels_matches_undistortPointsIter(n_dist, seed):
    rng = np.random.default_rng(1000 + 10 * n_dist + seed)
    cam = _random_camera(rng, n_dist)
    uv = rng.uniform([0.0, 0.0], [640.0, 480.0], size=(3000, 2))
    ref = cv2.undistortPointsIter(uv[:, None, :], cam.K, _cv_dist(cam), None, None, TIGHT)
    np.testing.assert_allclose(cam.undistort_pixels(uv, to_pixels=False), ref[:, 0], atol=1e-9)
    ref_px = cv2.undistortPointsIter(uv[:, None, :], cam.K, _cv_dist(cam), None, cam.K, TIGHT)
    np.testing.assert_allclose(cam.undistort_pixels(uv), ref_px[:, 0], atol=1e-9)


def test_default_undistortPoints_stops_short_where_we_converge():
    # OpenCV's default undistortPoints stops after 5 fixed-point steps; we converge fully:
    # re-distorting our answer gives the input back, re-distorting OpenCV's does not quite.
    cam = _random_camera(np.random.default_rng(3), 5)
    uv = np.random.default_rng(4).uniform([0, 0], [640, 480], size=(500, 2))
    ref = cv2.undistortPoints(uv[:, None, :], cam.K, _cv_dist(cam))[:, 0]
    ours = cam.undistort_pixels(uv, to_pixels=False)
    err_ours = np.abs(cam.pixels_from_normalized(cam.distort_normalized(ours)) - uv).max()
    err_cv = np.abs(cam.pixels_from_normalized(cam.distort_normalized(ref)) - uv).max()
    assert err_ours < 1e-9 < err_cv


@pytest.mark.parametrize("n_dist", [2, 4, 5])
def test_undistort_maps_match_initUndistortRectifyMap(n_dist):
    rng = np.random.default_rng(50 + n_dist)
    cam = _random_camera(rng, n_dist)
    K_new = cam.K.copy()
    K_new[0, 0] *= 0.8
    K_new[1, 1] *= 0.8
    R = rotation_from_rvec([0.02, -0.03, 0.01])
    for kn, r in [(None, None), (K_new, None), (K_new, R)]:
        ref_x, ref_y = cv2.initUndistortRectifyMap(
            cam.K, _cv_dist(cam), r, cam.K if kn is None else kn, (640, 480), cv2.CV_32FC1
        )
        mx, my = cam.undistort_maps(kn, R=r)
        # OpenCV computes in double and stores float32: ours rounds the same doubles.
        np.testing.assert_array_max_ulp(mx, ref_x, maxulp=1)
        np.testing.assert_array_max_ulp(my, ref_y, maxulp=1)
        mx64, my64 = cam.undistort_maps(kn, R=r, dtype=np.float64)
        assert mx64.dtype == np.float64
        np.testing.assert_allclose(mx64, ref_x, atol=1e-4)
        np.testing.assert_allclose(my64, ref_y, atol=1e-4)


def test_distort_maps_invert_undistort_maps_on_real_remap():
    cam = _random_camera(np.random.default_rng(9), 5)
    rng = np.random.default_rng(10)
    ideal = cv2.GaussianBlur(rng.integers(0, 255, (480, 640), dtype=np.uint8), (0, 0), 4)
    dx, dy = cam.distort_maps()
    ux, uy = cam.undistort_maps()
    recorded = cv2.remap(ideal, dx, dy, cv2.INTER_LINEAR)
    back = cv2.remap(recorded, ux, uy, cv2.INTER_LINEAR).astype(float)
    inner = (slice(80, 400), slice(100, 540))
    assert np.abs(back[inner] - ideal[inner]).mean() < 1.0


def test_distort_normalized_round_trip_to_machine_precision():
    for n_dist in (2, 4, 5):
        cam = _random_camera(np.random.default_rng(20 + n_dist), n_dist)
        xy = np.random.default_rng(30).uniform(-0.6, 0.6, size=(5000, 2))
        np.testing.assert_allclose(
            cam.undistort_normalized(cam.distort_normalized(xy)), xy, atol=1e-12
        )
