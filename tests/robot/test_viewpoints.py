"""Viewpoints planned from where the object was found (pure, no simulator)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from robot.aiming import aimed_flange_pose, look_at
from robot.collision import Box
from robot.errors import Unreachable
from robot.kinematics import T_base_ee, fk, ik
from robot.model import ASEA, check_joints
from robot.sim.camera import DEFAULT_T_EE_CAM
from robot.sim.obstacles import collision_world
from robot.sim.poses import viewpoint as sim_viewpoint
from robot.sim.world import ConveyorSpec
from robot.viewpoints import plan_viewpoint, plan_viewpoints

#: The nominal camera mounting before calibration (the camera 40 mm out along the approach
#: axis, turned a quarter about it): the backend's ``NOMINAL_T_EE_CAM``.
NOMINAL_T_EE_CAM = np.array(
    [[0.0, -1.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.04], [0.0, 0.0, 0.0, 1.0]]
)
WORLD = collision_world()
STATION = ConveyorSpec().station_point
H = 0.1


def _check_valid(v, point, height, T_ee_cam):
    """Joints in range, IK-consistent, camera axis through the target, clear of obstacles."""
    q = check_joints(v.q)
    np.testing.assert_allclose(T_base_ee(q), v.T_base_ee, atol=1e-12)
    np.testing.assert_allclose(v.T_base_ee @ T_ee_cam, v.T_base_cam, atol=1e-12)
    pose = fk(q)
    np.testing.assert_allclose(ik(pose, roll=q[4], seed=q), q, atol=1e-9)
    C, z = v.T_base_cam[:3, 3], v.T_base_cam[:3, 2]
    rel = v.target - C
    assert np.linalg.norm(rel - (rel @ z) * z) < 1e-5
    assert rel @ z == pytest.approx(v.distance_m, abs=1e-5)
    p = np.asarray(point, float)
    obj = Box("object", (p[0] - 0.18, p[1] - 0.18, p[2]), (p[0] + 0.18, p[1] + 0.18, p[2] + height))
    assert WORLD.with_boxes(obj).contacts(q) == []


@pytest.mark.parametrize("T_ee_cam", [NOMINAL_T_EE_CAM, DEFAULT_T_EE_CAM], ids=["nominal", "true"])
def test_station_views_are_reached_nominally(T_ee_cam):
    plan = plan_viewpoints(STATION, T_ee_cam=T_ee_cam, object_height_m=H, world=WORLD)
    assert [v.name for v in plan.views] == ["top", "inner", "outer"]
    assert [v.index for v in plan.views] == [1, 2, 3]
    np.testing.assert_allclose(plan.target, STATION + np.array([0.0, 0.0, H]))
    for v in plan.views:
        assert v.reached_nominal, v.reason
        assert v.reason == ""
        # The true camera sits 5 cm off the approach axis with a 1 deg sideways tilt: the
        # arm cannot take that out of its plane, the rest is exact.
        assert v.deviation_deg < (1e-6 if T_ee_cam is NOMINAL_T_EE_CAM else 1.5)
        _check_valid(v, STATION, H, T_ee_cam)
    top, inner, outer = plan.views
    assert top.tilt_deg == pytest.approx(0.0, abs=1.5)
    assert inner.tilt_deg == pytest.approx(30.0, abs=1.5)
    assert outer.tilt_deg == pytest.approx(30.0, abs=1.5)
    # Inner: the camera is on the column's side, looking outwards (+x); outer: looking back.
    assert inner.T_base_cam[0, 3] < STATION[0] < outer.T_base_cam[0, 3]
    assert inner.T_base_cam[0, 2] > 0 > outer.T_base_cam[0, 2]


def test_views_across_the_belt_are_replaced_where_needed_never_unreachable():
    spec = ConveyorSpec()
    replaced = 0
    for lateral in (-0.2, -0.1, 0.0, 0.1, 0.2):
        for y in (-0.6, -0.3, 0.0, 0.3, 0.6):
            point = (spec.centre_x_m + lateral, y, spec.surface_z_m)
            for view in ("top", "inner", "outer"):
                try:
                    v = plan_viewpoint(
                        point, view, T_ee_cam=DEFAULT_T_EE_CAM, object_height_m=H, world=WORLD
                    )
                except Unreachable:
                    continue
                _check_valid(v, point, H, DEFAULT_T_EE_CAM)
                if not v.reached_nominal:
                    replaced += 1
                    assert v.reason.startswith(f"nominal {view} view")
                    assert "replaced by tilt" in v.reason
                    assert 0.0 < v.deviation_deg <= 60.0 + 1.5 or v.deviation_deg < 1.5
                else:
                    assert v.deviation_deg < 1.5
    assert replaced >= 5


def test_replacement_is_the_nearest_in_angle():
    # Far side of the belt: the outer view at 30 deg needs too long a reach.
    point = (1.0, 0.0, 0.45)
    v = plan_viewpoint(point, "outer", T_ee_cam=NOMINAL_T_EE_CAM, object_height_m=H, world=WORLD)
    assert not v.reached_nominal
    assert 0.0 < v.deviation_deg < 30.0
    # Every tilt strictly nearer to the nominal (same side) fails at every distance.
    nearer = 30.0 - v.deviation_deg
    for s in np.arange(30.0, nearer + 1e-6, -2.5)[:-1]:
        for d in np.arange(0.30, 0.7001, 0.04):
            try:
                a = look_at(
                    np.array(point) + np.array([0.0, 0.0, H]),
                    phi_rad=math.radians(-90 - s),
                    distance_m=float(d),
                    T_ee_cam=NOMINAL_T_EE_CAM,
                )
            except Unreachable:
                continue
            obj = Box("object", (0.82, -0.18, 0.45), (1.18, 0.18, 0.55))
            assert WORLD.with_boxes(obj).collides(a.q)


def test_no_reachable_view_raises_with_reason():
    with pytest.raises(Unreachable, match="no top viewpoint"):
        plan_viewpoint((0.15, 0.0, 0.3), "top", T_ee_cam=NOMINAL_T_EE_CAM, object_height_m=H)


@pytest.mark.parametrize(
    ("point", "match"),
    [
        ((math.nan, 0.0, 0.45), "finite"),
        ((0.8, math.inf, 0.45), "finite"),
        ((2.5, 0.0, 0.45), r"outside the arm's workspace"),
        ((0.8, 0.0, -0.3), r"outside the arm's workspace"),
        ((0.8, 0.0), "3 finite numbers"),
        ("here", "3 numbers"),
    ],
)
def test_bad_points_are_refused_with_the_value(point, match):
    with pytest.raises(ValueError, match=match):
        plan_viewpoints(point, T_ee_cam=NOMINAL_T_EE_CAM)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"object_height_m": True}, "object_height_m"),
        ({"object_height_m": -0.1}, r"object_height_m .* got -0.1"),
        ({"object_height_m": math.nan}, "object_height_m"),
        ({"aim_height_fraction": 2.0}, "aim_height_fraction"),
        ({"distance_m": 5.0}, "distance"),
        ({"side_tilt_deg": math.nan}, "side_tilt_deg"),
        ({"roll_rad": 7.0}, "roll_rad"),
    ],
)
def test_bad_options_are_refused(kwargs, match):
    with pytest.raises(ValueError, match=match):
        plan_viewpoint(STATION, "inner", T_ee_cam=NOMINAL_T_EE_CAM, **kwargs)


def test_bad_view_names():
    with pytest.raises(ValueError, match="view must be one of"):
        plan_viewpoint(STATION, "side", T_ee_cam=NOMINAL_T_EE_CAM)
    with pytest.raises(ValueError, match="distinct names"):
        plan_viewpoints(STATION, T_ee_cam=NOMINAL_T_EE_CAM, views=("top", "top"))


def test_geometry_is_shared_with_the_simulators_named_poses_and_calibration():
    target = STATION + np.array([0.0, 0.0, H])
    for view, phi in (("top", -90.0), ("outer", -120.0)):
        q_sim = sim_viewpoint(target, view, distance_m=0.42)
        pose = aimed_flange_pose(target, phi_rad=math.radians(phi), distance_m=0.42)
        np.testing.assert_allclose(fk(q_sim), pose, atol=1e-9)
        # With the camera on the approach axis 4 cm past the flange, looking at the target
        # from 0.38 m is the same flange pose.
        a = look_at(target, phi_rad=math.radians(phi), distance_m=0.38, T_ee_cam=NOMINAL_T_EE_CAM)
        np.testing.assert_allclose(fk(a.q), pose, atol=1e-9)
        np.testing.assert_allclose(a.q, q_sim, atol=1e-7)
    assert ASEA.within_limits(a.q)
