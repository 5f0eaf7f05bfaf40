"""Planar pose geometry (vision.pose.geometry) against values worked out by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vision.camera import PinholeCamera
from vision.pose import (
    ObjectPose,
    PoseFailed,
    closest_points,
    object_rays,
    plane_motion,
    plane_points,
    pose_apart,
    predict_along_belt,
    rests_on_too_little,
    rigid_motion_2d,
    viewing_rays,
    yaw_of,
)

F, CX, CY = 500.0, 320.0, 240.0
CAM = PinholeCamera(np.array([[F, 0.0, CX], [0.0, F, CY], [0.0, 0.0, 1.0]]))


def _down(x: float, y: float, z: float) -> np.ndarray:
    """T_base_cam of a camera at (x, y, z) looking straight down: cam x = base x, cam y =
    base -y, cam z = base -z (OpenCV frame)."""
    T = np.diag([1.0, -1.0, -1.0, 1.0])
    T[:3, 3] = (x, y, z)
    return T


def _rot(yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s], [s, c]])


def _pose(x: float, y: float, yaw: float, **kw) -> ObjectPose:
    T = np.eye(4)
    T[:2, :2] = _rot(yaw)
    T[:2, 3] = (x, y)
    return ObjectPose(T, yaw, 0.0, 10, **kw)


def test_plane_points_of_a_camera_looking_down():
    # Camera 1.0 m above the base at (0.2, 0.1); the plane z = 0.25 is 0.75 m in front.
    # Pixel (u, v) has normalised (x, y) = ((u - cx) / f, (v - cy) / f); in the base frame
    # the ray is (x, -y, -1), so it meets the plane at (0.2 + 0.75 x, 0.1 - 0.75 y, 0.25).
    px = np.array([[CX, CY], [CX + 100.0, CY], [CX, CY + 50.0], [CX - 200.0, CY - 100.0]])
    got = plane_points(px, CAM, _down(0.2, 0.1, 1.0), 0.25)
    want = np.array(
        [
            [0.2, 0.1, 0.25],
            [0.2 + 0.75 * 0.2, 0.1, 0.25],
            [0.2, 0.1 - 0.75 * 0.1, 0.25],
            [0.2 - 0.75 * 0.4, 0.1 + 0.75 * 0.2, 0.25],
        ]
    )
    np.testing.assert_allclose(got, want, atol=1e-12)


def test_plane_points_refuses_a_plane_behind_or_along_the_camera():
    with pytest.raises(PoseFailed, match="behind the camera"):
        plane_points(np.array([[CX, CY]]), CAM, _down(0.0, 0.0, 1.0), 2.0)
    side = np.eye(4)  # a camera looking level along base -y: its centre ray never meets z = 0
    side[:3, :3] = [[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]
    with pytest.raises(PoseFailed, match="parallel"):
        plane_points(np.array([[CX, CY]]), CAM, side, 0.0)


def test_rigid_motion_2d_recovers_a_known_turn_and_shift():
    a = np.array([[0.0, 0.0], [0.1, 0.0], [0.1, 0.05], [-0.02, 0.08], [0.03, -0.04]])
    yaw, t = math.radians(30.0), np.array([0.4, -0.25])
    R, tt, resid = rigid_motion_2d(a, a @ _rot(yaw).T + t)
    np.testing.assert_allclose(R, [[math.sqrt(3) / 2, -0.5], [0.5, math.sqrt(3) / 2]], atol=1e-12)
    np.testing.assert_allclose(tt, t, atol=1e-12)
    assert resid == pytest.approx(0.0, abs=1e-12)


def test_rigid_motion_2d_of_a_reflection_is_a_rotation_and_its_residual_is_rms():
    # b is a mirrored: the best rotation (no reflection allowed) of the two points (+-1, 0)
    # onto (-+1, 0) is a half turn, exactly, and leaves no residual.
    a = np.array([[1.0, 0.0], [-1.0, 0.0]])
    R, t, resid = rigid_motion_2d(a, a * [-1.0, 1.0])
    assert np.linalg.det(R) == pytest.approx(1.0)
    np.testing.assert_allclose(R, -np.eye(2), atol=1e-12)
    assert resid == pytest.approx(0.0, abs=1e-12)
    # Two points 2 apart against two points 4 apart: no scale, so each ends 1 off.
    R, t, resid = rigid_motion_2d(a, 2.0 * a)
    np.testing.assert_allclose(R, np.eye(2), atol=1e-12)
    np.testing.assert_allclose(t, [0.0, 0.0], atol=1e-12)
    assert resid == pytest.approx(1.0)


@pytest.mark.parametrize(
    ("a", "b"),
    [(np.zeros((1, 2)), np.zeros((1, 2))), (np.zeros((3, 2)), np.zeros((4, 2))),
     (np.zeros((3, 3)), np.zeros((3, 3)))],
)  # fmt: skip
def test_rigid_motion_2d_refuses_bad_shapes(a, b):
    with pytest.raises(ValueError, match=r"shape \(N, 2\)"):
        rigid_motion_2d(a, b)


def test_plane_motion_of_a_camera_that_moved_is_the_opposite_shift():
    # The same pixels seen from a camera moved +0.1 m in x lie 0.1 m further in x on the
    # plane: the points moved +0.1 m, no turn.
    px = np.array([[100.0, 100.0], [500.0, 120.0], [300.0, 400.0], [320.0, 240.0]])
    R, t, resid = plane_motion(px, px, CAM, _down(0.0, 0.0, 0.8), _down(0.1, 0.0, 0.8), 0.0)
    np.testing.assert_allclose(R, np.eye(2), atol=1e-12)
    np.testing.assert_allclose(t, [0.1, 0.0], atol=1e-12)
    assert resid == pytest.approx(0.0, abs=1e-12)


def test_viewing_and_object_rays_of_a_camera_looking_down():
    px = np.array([[CX, CY], [CX + F, CY]])  # the centre, and 45 deg to the camera's right
    np.testing.assert_allclose(viewing_rays(px, CAM, _down(0, 0, 1)), [[0, 0, -1], [1, 0, -1]],
                               atol=1e-12)  # fmt: skip
    T_obj = np.eye(4)
    T_obj[:3, 3] = (0.5, 0.0, 0.0)
    T_obj[:2, :2] = _rot(math.pi / 2)  # the object frame turned a quarter: base x = obj -y
    centre, rays, R = object_rays(px, CAM, _down(0.5, 0.0, 1.0), T_obj)
    np.testing.assert_allclose(centre, [0.0, 0.0, 1.0], atol=1e-12)
    s = 1 / math.sqrt(2)
    np.testing.assert_allclose(rays, [[0.0, 0.0, -1.0], [0.0, -s, -s]], atol=1e-12)
    np.testing.assert_allclose(R @ [0.0, 0.0, 1.0], [0.0, 0.0, -1.0], atol=1e-12)


def test_closest_points_of_skew_perpendicular_and_parallel_lines():
    o1, d1 = np.array([0.0, 0.0, 0.0]), np.array([1.0, 0.0, 0.0])
    o2, d2 = np.array([2.0, -3.0, 1.0]), np.array([0.0, 1.0, 0.0])
    P1, P2, s, t, sin2 = closest_points(o1, d1, o2, d2)
    # The common perpendicular is the vertical through (2, 0): s = 2, t = 3.
    np.testing.assert_allclose(P1, [2.0, 0.0, 0.0])
    np.testing.assert_allclose(P2, [2.0, 0.0, 1.0])
    assert (float(s), float(t), float(sin2)) == pytest.approx((2.0, 3.0, 1.0))
    # The x axis and a line at 60 deg to it through (1, 1, 0) meet where y = 0 on the
    # second line: at x = 1 - 1 / tan(60 deg) = 1 - 1 / sqrt(3).
    d3 = np.array([0.5, math.sqrt(3) / 2, 0.0])
    P1, P2, s, t, sin2 = closest_points(o1, d1, np.array([1.0, 1.0, 0.0]), d3)
    np.testing.assert_allclose(P1, [1.0 - 1.0 / math.sqrt(3), 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(P2, P1, atol=1e-12)
    assert float(t) == pytest.approx(-2.0 / math.sqrt(3))
    assert float(sin2) == pytest.approx(0.75)
    # Parallel lines: no division by zero, s = t = 0.
    P1, P2, s, t, sin2 = closest_points(o1, d1, o2, d1)
    assert (float(s), float(t), float(sin2)) == (0.0, 0.0, 0.0)
    np.testing.assert_allclose(P2, o2)


def test_closest_points_works_row_by_row():
    o1 = np.zeros((2, 3))
    d1 = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    o2 = np.array([[0.0, 0.0, 2.0], [5.0, 0.0, -1.0]])
    d2 = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])
    P1, P2, _s, _t, _ = closest_points(o1, d1, o2, d2)
    np.testing.assert_allclose(P1, [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]], atol=1e-12)
    np.testing.assert_allclose(P2, [[0.0, 0.0, 2.0], [0.0, 0.0, -1.0]], atol=1e-12)


def test_yaw_pose_apart_and_the_belts_travel():
    a = _pose(0.1, 0.2, math.radians(170.0))
    b = _pose(0.13, 0.24, math.radians(-170.0))
    assert yaw_of(a.T_base_obj) == pytest.approx(math.radians(170.0))
    d, dyaw = pose_apart(a, b)
    assert d == pytest.approx(0.05)  # a 3-4-5 triangle, centimetres
    assert dyaw == pytest.approx(math.radians(20.0))  # across +-180 deg
    moved = predict_along_belt(a, 0.3)
    np.testing.assert_allclose(moved.T_base_obj[:3, 3], [0.1, 0.5, 0.0])
    assert moved.yaw_rad == a.yaw_rad
    moved = predict_along_belt(a, 0.5, direction=np.array([3.0, 4.0, 0.0]))
    np.testing.assert_allclose(moved.T_base_obj[:3, 3], [0.4, 0.6, 0.0])
    for bad in (math.nan, math.inf, 5.1):
        with pytest.raises(PoseFailed, match="within 5 m"):
            predict_along_belt(a, bad)


def test_which_poses_rest_on_too_little():
    assert rests_on_too_little(None)
    assert rests_on_too_little(_pose(0, 0, 0, method="plane", views=3))
    assert rests_on_too_little(_pose(0, 0, 0, method="parallax", views=1))
    assert not rests_on_too_little(_pose(0, 0, 0, method="parallax", views=2))
