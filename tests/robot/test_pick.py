"""The pick-and-place planner (pure: no simulator) and the ideal driver's gripper."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from robot.collision import Box, CollisionWorld
from robot.drivers import IdealDriver
from robot.drivers.base import RobotDriver
from robot.errors import RobotBusy, Unreachable
from robot.kinematics import T_base_ee, ik
from robot.model import ASEA, check_joints
from robot.pick import T_EE_SUCTION_CUP, execute_pick_place, plan_pick_place, tool_flange_pose


def _obj(x=0.8, y=0.0, z=0.45, yaw=0.3):
    T = np.eye(4)
    T[:2, :2] = [[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]]
    T[:3, 3] = (x, y, z)
    return T


BELT = Box("conveyor", (0.54, -1.3, 0.0), (1.06, 1.3, 0.45))
BIN = Box("bin", (0.11, 0.41, 0.0), (0.51, 0.81, 0.25))
WORLD = CollisionWorld((BELT, BIN))
DROP = (0.31, 0.61, 0.25)


@pytest.mark.parametrize("roll", [0.0, 0.8, -2.0])
def test_tool_flange_pose_puts_the_lip_on_the_point(roll):
    p = np.array([0.75, 0.2, 0.6])
    q = ik(tool_flange_pose(p, roll_rad=roll), roll=roll, seed=ASEA.q_ready)
    T_lip = T_base_ee(q) @ T_EE_SUCTION_CUP
    np.testing.assert_allclose(T_lip[:3, 3], p, atol=1e-9)
    np.testing.assert_allclose(T_lip[:3, 2], [0, 0, -1], atol=1e-12)


def test_plan_at_the_station():
    T = _obj()
    plan = plan_pick_place(ASEA.q_ready, T, 0.1, DROP, object_radius_m=0.15, world=WORLD)
    names = [s.name for s in plan.steps]
    assert names == [
        "approach", "descend", "grip", "lift", "transfer", "lower", "release", "retreat", "return",
    ]  # fmt: skip
    assert [s.grip for s in plan.steps if s.trajectory is None] == [True, False]
    moves = [s.trajectory for s in plan.steps if s.trajectory is not None]
    for a, b in itertools.pairwise(moves):
        np.testing.assert_allclose(a.goal, b.start, atol=1e-9)  # each starts where the last ended
        check_joints(b.q)
    np.testing.assert_allclose(moves[0].start, ASEA.q_ready)
    np.testing.assert_allclose(moves[-1].goal, ASEA.q_ready)
    # The lip presses 4 mm into the top face's centre, pointing down the object's z axis.
    np.testing.assert_allclose(plan.T_base_lip_grasp[:3, 3], [0.8, 0.0, 0.546], atol=1e-6)
    np.testing.assert_allclose(plan.T_base_lip_grasp[:3, 2], [0, 0, -1], atol=1e-9)
    # The part's footprint centre is over the drop point, its bottom 3 cm above the rim.
    lip_drop = (T_base_ee(plan.q_drop) @ T_EE_SUCTION_CUP)[:3, 3]
    np.testing.assert_allclose(lip_drop, [0.31, 0.61, 0.25 + 0.03 + 0.096], atol=1e-6)
    assert plan.duration_s > 5.0
    for q in (plan.q_grasp, plan.q_drop):
        assert not WORLD.collides(q)


def test_off_centre_grasp_point_still_drops_the_footprint_centre_over_the_bin():
    T = _obj(yaw=1.1)
    g = np.array([0.03, -0.02, 0.08])
    plan = plan_pick_place(ASEA.q_ready, T, 0.1, DROP, grasp_obj=g, world=WORLD)
    lip_grasp = plan.T_base_lip_grasp
    T_lip_obj = np.linalg.inv(lip_grasp) @ T  # the weld made at the grasp
    T_drop = T_base_ee(plan.q_drop) @ T_EE_SUCTION_CUP @ T_lip_obj
    np.testing.assert_allclose(T_drop[:2, 3], DROP[:2], atol=1e-6)


@pytest.mark.parametrize(
    ("T", "drop", "match"),
    [
        (_obj(x=1.45), DROP, "pre-grasp pose"),
        (_obj(x=0.8), (1.6, 0.0, 0.25), "above the bin"),
        (_obj(x=0.8), (0.2, 0.0, 0.25), "above the bin"),
    ],
)
def test_unreachable_stages_are_named(T, drop, match):
    with pytest.raises(Unreachable, match=match):
        plan_pick_place(ASEA.q_ready, T, 0.1, drop, world=WORLD)


def test_collisions_are_refused_with_the_reason():
    pole = Box("pole", (0.3, 0.15, 0.0), (0.5, 0.3, 1.8))  # between the belt and the bin
    with pytest.raises(Unreachable, match=r"transfer: collision .* pole"):
        plan_pick_place(ASEA.q_ready, _obj(), 0.1, DROP, world=WORLD.with_boxes(pole))


def test_a_tilted_object_is_refused():
    T = _obj()
    a = math.radians(10)
    T[:3, :3] = np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])
    with pytest.raises(Unreachable, match="off vertical"):
        plan_pick_place(ASEA.q_ready, T, 0.1, DROP)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"T_base_obj": np.full((4, 4), np.nan)}, "finite 4x4"),
        ({"T_base_obj": np.eye(3)}, "finite 4x4"),
        ({"T_base_obj": np.diag([2.0, 1, 1, 1])}, "rigid"),
        ({"object_height_m": True}, "object_height_m"),
        ({"object_height_m": 0.0}, "object_height_m"),
        ({"drop_point": (math.inf, 0, 0)}, "drop_point"),
        ({"press_m": -1.0}, "press_m"),
        ({"roll_rad": math.nan}, "roll_rad"),
        ({"grasp_obj": (0, 0, 0.5)}, "grasp_obj"),
    ],
)
def test_bad_inputs_are_refused_with_the_value(kwargs, match):
    args = {"T_base_obj": _obj(), "object_height_m": 0.1, "drop_point": DROP} | kwargs
    with pytest.raises(ValueError, match=match):
        plan_pick_place(
            ASEA.q_ready, args.pop("T_base_obj"), args.pop("object_height_m"),
            args.pop("drop_point"), **args,
        )  # fmt: skip


async def test_ideal_driver_gripper_bookkeeping_and_a_pick_run():
    d = IdealDriver(time_scale=50.0, rate_hz=100.0)
    assert isinstance(d, RobotDriver)
    await d.connect()
    try:
        r = await d.grip(True)
        assert r.on and r.holding and d.state.gripper_on and d.state.holding
        r = await d.grip(False)
        assert not r.on and not r.holding and r.detail == "released"
        with pytest.raises(ValueError, match="True or False"):
            await d.grip(1)  # type: ignore[arg-type]
        plan = plan_pick_place(d.state.q, _obj(), 0.1, DROP, world=WORLD, speed=1.0)
        out = await execute_pick_place(d, plan)
        assert out.ok and out.stage == "return" and out.grip is not None and out.grip.holding
        assert not d.state.gripper_on
        await d.estop()
        with pytest.raises(RobotBusy):
            await d.grip(True)
    finally:
        await d.close()
