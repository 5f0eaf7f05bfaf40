"""The part's height from the teach's silhouettes (:mod:`backend.recognition.geometry`),
on regions rendered exactly from boxes and a cylinder seen by a pinhole camera."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from backend.recognition.geometry import Silhouette, measure_height
from vision.camera import PinholeCamera
from vision.errors import InvalidInput

SURFACE_Z = 0.45
CAMERA = PinholeCamera.from_fov(60.0, width=640, height=480)


def _look_at(eye, target, up=(0.0, 1.0, 0.0)):
    """T_base_cam of a camera at ``eye`` looking at ``target`` (OpenCV: +z forward)."""
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, np.asarray(up, float))
    if np.linalg.norm(x) < 1e-6:
        x = np.cross(z, [1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, :3] = np.stack([x, y, z], axis=1)
    T[:3, 3] = eye
    return T


def _mask(points_base, T_base_cam):
    """The silhouette of a convex solid given by its surface points: their projections'
    convex hull, filled."""
    T_cam_base = np.linalg.inv(T_base_cam)
    p = points_base @ T_cam_base[:3, :3].T + T_cam_base[:3, 3]
    uv = CAMERA.project(p)
    hull = cv2.convexHull(np.round(uv).astype(np.int32))
    m = np.zeros((480, 640), np.uint8)
    cv2.fillConvexPoly(m, hull, 1)
    return m.astype(bool)


def _box(w, d, h, yaw=0.0, at=(0.8, 0.0)):
    xs, ys, zs = np.meshgrid([-w / 2, w / 2], [-d / 2, d / 2], [0.0, h], indexing="ij")
    pts = np.stack([xs.ravel(), ys.ravel(), zs.ravel()], axis=1)
    c, s = math.cos(yaw), math.sin(yaw)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    return pts @ R.T + [at[0], at[1], SURFACE_Z]


def _cylinder(r, h, at=(0.8, 0.0)):
    a = np.linspace(0, 2 * math.pi, 180, endpoint=False)
    ring = np.stack([r * np.cos(a), r * np.sin(a)], axis=1)
    out = [np.column_stack([ring, np.full(len(a), z)]) for z in (0.0, h)]
    return np.concatenate(out) + np.array([at[0], at[1], SURFACE_Z])


def _shots(points, at=(0.8, 0.0)):
    """The top view from 0.45 m above and two side views 30 deg off vertical (inner and
    outer side, as the teach's planner places them)."""
    target = np.array([at[0], at[1], SURFACE_Z + 0.05])
    top = _look_at(target + np.array([0.0, 0.0, 0.45]), target)
    sides = []
    for sign in (-1.0, 1.0):
        off = np.array([sign * math.sin(math.radians(30)), 0.0, math.cos(math.radians(30))])
        sides.append(_look_at(target + 0.45 * off, target))
    return Silhouette(_mask(points, top), top), [Silhouette(_mask(points, T), T) for T in sides]


@pytest.mark.parametrize(
    ("solid", "height"),
    [
        (_box(0.12, 0.08, 0.06), 0.06),
        (_box(0.10, 0.10, 0.15, yaw=0.5), 0.15),
        (_box(0.20, 0.15, 0.02, yaw=-0.3), 0.02),
        (_cylinder(0.05, 0.11), 0.11),
    ],
)
def test_the_height_of_a_solid_from_its_silhouettes(solid, height):
    top, sides = _shots(solid)
    got = measure_height(top, sides, CAMERA, surface_z_m=SURFACE_Z)
    assert got.height_m is not None, got.note
    assert got.height_m == pytest.approx(height, abs=0.004), got
    assert len(got.per_view_m) == 2
    assert got.public()["height_mm"] == pytest.approx(height * 1e3, abs=4.0)


def test_one_side_view_is_enough():
    top, sides = _shots(_box(0.12, 0.08, 0.09))
    got = measure_height(top, sides[:1], CAMERA, surface_z_m=SURFACE_Z)
    assert got.height_m == pytest.approx(0.09, abs=0.004)


def test_no_region_gives_no_height_and_says_why():
    top, sides = _shots(_box(0.12, 0.08, 0.06))
    empty = Silhouette(np.zeros((480, 640), bool), top.T_base_cam)
    got = measure_height(empty, sides, CAMERA, surface_z_m=SURFACE_Z)
    assert got.height_m is None and "top view" in got.note
    blank = [Silhouette(np.zeros((480, 640), bool), s.T_base_cam) for s in sides]
    got = measure_height(top, blank, CAMERA, surface_z_m=SURFACE_Z)
    assert got.height_m is None and "side view" in got.note


def test_bad_input_is_refused():
    top, sides = _shots(_box(0.12, 0.08, 0.06))
    with pytest.raises(InvalidInput, match="sides"):
        measure_height(top, [], CAMERA, surface_z_m=SURFACE_Z)
    with pytest.raises(InvalidInput, match="max_height_m"):
        measure_height(top, sides, CAMERA, surface_z_m=SURFACE_Z, max_height_m=2.0)
    with pytest.raises(InvalidInput, match="surface_z_m"):
        measure_height(top, sides, CAMERA, surface_z_m=float("nan"))
    bad = Silhouette(top.mask, np.full((4, 4), np.inf))
    with pytest.raises(InvalidInput, match="T_base_cam"):
        measure_height(bad, sides, CAMERA, surface_z_m=SURFACE_Z)
