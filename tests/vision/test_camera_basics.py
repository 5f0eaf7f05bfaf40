import cv2
import numpy as np
import pytest

from vision.camera import PinholeCamera


@pytest.fixture
def cam():
    K = np.array([[520.0, 0.0, 318.0], [0.0, 515.0, 243.0], [0.0, 0.0, 1.0]])
    return PinholeCamera(K, [-0.28, 0.09, 0.0012, -0.0008, -0.015])


def test_projection_agrees_with_opencv(cam):
    rng = np.random.default_rng(4)
    P = rng.uniform([-1, -0.8, 1.5], [1, 0.8, 4.0], size=(2000, 3))
    ref, _ = cv2.projectPoints(P, np.zeros(3), np.zeros(3), cam.K, cam.dist)
    np.testing.assert_allclose(cam.project(P), ref[:, 0], atol=1e-9)


def test_undistortion_inverts_distortion(cam):
    rng = np.random.default_rng(5)
    xy = rng.uniform(-0.5, 0.5, size=(2000, 2))
    back = cam.undistort_normalized(cam.distort_normalized(xy))
    np.testing.assert_allclose(back, xy, atol=1e-12)


def test_distort_and_undistort_maps_are_inverse(cam):
    mx, my = cam.undistort_maps()
    dx, dy = cam.distort_maps()
    # A pixel of the undistorted image maps to a distorted position; the distort map at
    # that position leads back to the start.
    v, u = 240, 320
    su, sv = mx[v, u], my[v, u]
    bu = cv2.remap(dx, np.array([[su]], np.float32), np.array([[sv]], np.float32), cv2.INTER_LINEAR)
    bv = cv2.remap(dy, np.array([[su]], np.float32), np.array([[sv]], np.float32), cv2.INTER_LINEAR)
    assert abs(bu[0, 0] - u) < 0.05 and abs(bv[0, 0] - v) < 0.05
