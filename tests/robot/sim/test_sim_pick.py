"""Pick and sort end to end in the simulator: plan with robot.pick, execute with SimDriver."""

from __future__ import annotations

import math

import numpy as np
import pytest

from robot.pick import PickPlan, execute_pick_place, plan_pick_place
from robot.sim import SimDriver, SimEngine
from robot.sim.catalogue import CATALOGUE
from robot.sim.gripper import suction_point
from robot.sim.obstacles import collision_world


def _size(name: str) -> tuple[float, float]:
    b = CATALOGUE[name].geometry().bounds
    return float(b[1, 2]), float(np.abs(b[:, :2]).max())


def _plan(engine: SimEngine, T_base_obj: np.ndarray, name: str, bin_name: str) -> PickPlan:
    height, radius = _size(name)
    return plan_pick_place(
        engine.arm_state().q,
        T_base_obj,
        height,
        engine.config.layout.bin(bin_name).drop_point,
        object_radius_m=radius,
        grasp_obj=suction_point(name),
        world=collision_world(engine.config.layout),
    )


@pytest.fixture
async def cell():
    engine = SimEngine()
    engine.set_joints(engine.arm_model.q_ready)
    engine.configure_conveyor(mode="index", running=False)
    driver = SimDriver(engine, time_scale=20.0)
    await driver.connect()
    yield engine, driver
    await driver.close()
    engine.stop()


def _spawn(engine: SimEngine, name: str, yaw: float):
    spec = engine.config.layout.conveyor
    return engine.spawn(name, s_m=spec.station_s_m, yaw_rad=yaw)


@pytest.mark.parametrize(
    ("name", "bin_name"),
    [("wheel-5spoke", "bin-wheel-5spoke"), ("valve-block", "reject")],
)
async def test_pick_at_the_true_pose_lands_in_the_named_bin(cell, name, bin_name):
    engine, driver = cell
    truth = _spawn(engine, name, 0.7)
    plan = _plan(engine, truth.T_base_obj, name, bin_name)
    outcome = await execute_pick_place(driver, plan)
    assert outcome.ok, (outcome.stage, outcome.reason)
    assert outcome.grip is not None and outcome.grip.part_id == truth.id
    assert [m.completed for m in outcome.moves] == [True] * len(outcome.moves)
    # Tracking with the part on the cup (lift, transfer, lowering) stays tight.
    assert max(m.max_tracking_error_rad for m in outcome.moves) < 2e-3
    bins = engine.bins()
    assert bins[bin_name] == (truth.id,)
    assert sum(len(v) for v in bins.values()) == 1
    landing = engine.landings()[-1]
    centre = engine.config.layout.bin(bin_name).drop_point
    assert np.linalg.norm(landing.position[:2] - centre[:2]) < 0.01
    assert engine.objects() == [] and engine.held_object() is None
    assert not driver.state.gripper_on and not driver.state.holding
    np.testing.assert_allclose(driver.state.q, engine.arm_model.q_ready, atol=1e-3)


async def test_pick_with_a_few_mm_of_pose_error_still_picks(cell):
    engine, driver = cell
    name = "gear-housing"
    truth = _spawn(engine, name, -0.4)
    T_est = truth.T_base_obj.copy()
    T_est[:3, 3] += (0.004, -0.003, 0.0)  # 5 mm off
    a = math.radians(1.0)
    Rz = np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])
    T_est[:3, :3] = Rz @ T_est[:3, :3]
    plan = _plan(engine, T_est, name, "bin-gear-housing")
    outcome = await execute_pick_place(driver, plan)
    assert outcome.ok, (outcome.stage, outcome.reason)
    assert engine.bins()["bin-gear-housing"] == (truth.id,)


async def test_a_missed_part_is_reported_and_the_arm_backs_off(cell):
    engine, driver = cell
    name = "gear-housing"
    truth = _spawn(engine, name, 0.0)
    T_wrong = truth.T_base_obj.copy()
    T_wrong[1, 3] += 0.5  # nothing there
    plan = _plan(engine, T_wrong, name, "bin-gear-housing")
    outcome = await execute_pick_place(driver, plan)
    assert not outcome.ok and outcome.stage == "grip" and "no part held" in outcome.reason
    assert not driver.state.gripper_on
    assert [o.id for o in engine.objects()] == [truth.id]
    # Backed off up the descent line, to the pre-grasp pose.
    approach = next(s for s in plan.steps if s.name == "approach").trajectory
    np.testing.assert_allclose(driver.state.q, approach.goal, atol=1e-3)
