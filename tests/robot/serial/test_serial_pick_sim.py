"""Pick and sort over the serial line: SerialDriver -> pseudo-terminal -> emulator -> simulator."""

from __future__ import annotations

import numpy as np
import pytest

from robot.drivers.serial.emulator import Emulator
from robot.pick import execute_pick_place, plan_pick_place
from robot.sim import SimDriver, SimEngine
from robot.sim.catalogue import CATALOGUE
from robot.sim.gripper import suction_point
from robot.sim.obstacles import collision_world


@pytest.fixture
async def serial_cell(tmp_path, make_driver):
    engine = SimEngine()
    engine.set_joints(engine.arm_model.q_ready)
    engine.configure_conveyor(mode="index", running=False)
    sim = SimDriver(engine, time_scale=20.0)
    await sim.connect()
    emu = Emulator(sim, link=str(tmp_path / "robot-tty"), rate_hz=50.0, seed=7, watchdog_s=5.0)
    await emu.start()
    # Lenient timings: the simulator's physics thread shares the CPU with the serial stack.
    driver = make_driver(emu.path, silence_timeout_s=5.0, command_timeout_s=5.0)
    await driver.connect()
    yield engine, driver
    await driver.close()
    await emu.close()
    await sim.close()
    engine.stop()


async def test_pick_and_sort_through_the_serial_stack(serial_cell):
    engine, driver = serial_cell
    name = "junction-box"
    spec = engine.config.layout.conveyor
    truth = engine.spawn(name, s_m=spec.station_s_m, yaw_rad=0.2)
    b = CATALOGUE[name].geometry().bounds
    plan = plan_pick_place(
        driver.state.q,
        truth.T_base_obj,
        float(b[1, 2]),
        engine.config.layout.bin("bin-junction-box").drop_point,
        object_radius_m=float(np.abs(b[:, :2]).max()),
        grasp_obj=suction_point(name),
        world=collision_world(engine.config.layout),
        speed=1.0,
    )
    outcome = await execute_pick_place(driver, plan)
    assert outcome.ok, (outcome.stage, outcome.reason)
    assert outcome.grip is not None and outcome.grip.holding
    assert engine.bins()["bin-junction-box"] == (truth.id,)
    assert not driver.state.gripper_on
