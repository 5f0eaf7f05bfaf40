"""The object pose from the top view's homography (vision.pose) on exact geometry."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from vision.camera import PinholeCamera
from vision.pose import PoseFailed, estimate_pose, plane_points, predict_along_belt

K = np.array([[600.0, 0, 319.5], [0, 600.0, 239.5], [0, 0, 1]])
CAM = PinholeCamera(K, np.zeros(5), width=640, height=480)


def _down(x, y, z, roll=0.0):
    """A camera at (x, y, z) looking straight down, turned ``roll`` about its axis."""
    T = np.eye(4)
    Rz = np.array(
        [[math.cos(roll), -math.sin(roll), 0], [math.sin(roll), math.cos(roll), 0], [0, 0, 1]]
    )
    T[:3, :3] = np.diag([1.0, -1.0, -1.0]) @ Rz
    T[:3, 3] = (x, y, z)
    return T


def _project(T_base_cam, pts):
    T = np.linalg.inv(T_base_cam)
    pc = pts @ T[:3, :3].T + T[:3, 3]
    uv = pc @ K.T
    return uv[:, :2] / uv[:, 2:]


def _planar(yaw, tx, ty, z):
    T = np.eye(4)
    T[:2, :2] = [[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]]
    T[:3, 3] = (tx, ty, z)
    return T


@pytest.mark.parametrize("yaw,dx,dy", [(0.0, 0.0, 0.0), (1.3, 0.004, -0.003), (-2.9, -0.01, 0.02)])
def test_recovers_the_planar_motion(yaw, dx, dy):
    z_top = 0.55
    T_view = _down(0.8, 0.0, 0.95, roll=math.radians(120))
    T_now = _down(0.8, 0.0, 0.95)
    taught = _planar(0.2, 0.8, 0.0, 0.45)
    truth = _planar(0.2 + yaw, 0.8 + dx, dy, 0.45)
    # Points of the top face in the object frame, seen taught and now: the exact homography.
    rng = np.random.default_rng(0)
    local = np.c_[rng.uniform(-0.08, 0.08, (30, 2)), np.full(30, z_top - 0.45), np.ones(30)]
    a = _project(T_view, (local @ taught.T)[:, :3])
    b = _project(T_now, (local @ truth.T)[:, :3])
    H, _ = cv2.findHomography(a, b)
    mask = np.zeros((480, 640), bool)
    lo, hi = a.min(0).astype(int), a.max(0).astype(int)
    mask[lo[1] : hi[1], lo[0] : hi[0]] = True
    pose = estimate_pose(
        H, camera=CAM, T_base_cam_view=T_view, T_base_cam_now=T_now, T_base_obj_taught=taught,
        z_plane_m=z_top, view_mask=mask, view_shape=(480, 640),
    )  # fmt: skip
    assert np.allclose(pose.T_base_obj[:3, 3], truth[:3, 3], atol=1e-6)
    assert abs(math.remainder(pose.yaw_rad - (0.2 + yaw), 2 * math.pi)) < 1e-6
    moved = predict_along_belt(pose, 0.1)
    assert moved.T_base_obj[1, 3] == pytest.approx(pose.T_base_obj[1, 3] + 0.1)


def test_plane_points_inverts_projection():
    T = _down(0.7, 0.1, 1.0)
    p = np.array([[0.72, 0.05, 0.45], [0.6, 0.2, 0.45]])
    assert np.allclose(plane_points(_project(T, p), CAM, T, 0.45), p, atol=1e-9)


def test_degenerate_homography_and_bad_travel_are_refused():
    T = _down(0.8, 0.0, 0.95)
    with pytest.raises(PoseFailed):
        estimate_pose(np.zeros((3, 3)), camera=CAM, T_base_cam_view=T, T_base_cam_now=T,
                      T_base_obj_taught=np.eye(4), z_plane_m=0.5, view_mask=None, view_shape=(480, 640))  # fmt: skip
    # A projective warp that is no rigid motion on the plane: refused by the residual.
    H = np.array([[3.0, 0.5, 0], [0.0, 0.2, 0], [0.001, 0, 1]])
    with pytest.raises(PoseFailed, match="RMS"):
        estimate_pose(H, camera=CAM, T_base_cam_view=T, T_base_cam_now=T,
                      T_base_obj_taught=np.eye(4), z_plane_m=0.5, view_mask=None, view_shape=(480, 640))  # fmt: skip
    pose = estimate_pose(np.eye(3), camera=CAM, T_base_cam_view=T, T_base_cam_now=T,
                         T_base_obj_taught=np.eye(4), z_plane_m=0.5, view_mask=None, view_shape=(480, 640))  # fmt: skip
    with pytest.raises(PoseFailed):
        predict_along_belt(pose, float("nan"))
