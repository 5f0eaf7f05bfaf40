"""Emergency stop overtakes queued commands; stop and e-stop end moves like the ideal driver."""

import asyncio

import numpy as np
import pytest

from robot.drivers.serial import FaultConfig
from robot.drivers.serial import frames as fr
from robot.errors import RobotBusy
from robot.model import ASEA
from robot.trajectory import plan_joint_move


async def test_estop_is_acknowledged_first_and_queued_motion_never_runs(driver, emulator):
    emulator.fault = FaultConfig(process_delay_s=0.03)  # a slow controller: commands pile up
    traj = plan_joint_move(driver.state.q, ASEA.q_ready, rate_hz=50.0)
    assert traj.t_s.size > 30
    upload = asyncio.create_task(driver.move(traj))
    async with asyncio.timeout(2.0):
        while not any(isinstance(c, fr.TrajPoint) for c in emulator.received):
            await asyncio.sleep(0.005)
    await asyncio.sleep(0.05)  # host queue and controller queue are both busy now
    before = len(emulator.replies)
    await driver.estop()
    with pytest.raises(RobotBusy, match="emergency stop"):
        await upload
    after = list(emulator.replies)[before:]
    # Points the controller finished while the stop was on its way may be answered first;
    # from the stop's acknowledgement on, every queued command is flushed, none executed.
    i = next(k for k, r in enumerate(after) if isinstance(r, fr.Ack) and r.verb == "ESTOP")
    assert all(isinstance(r, fr.Ack) and r.verb == "TP" for r in after[:i]), after[:i]
    flushed = [r for r in after[i + 1 :] if isinstance(r, fr.Nak)]
    assert flushed and all(r.code == "ESTOP" for r in flushed), flushed  # queued on the controller
    received = [c.VERB for c in emulator.received]
    assert "RUN" not in received  # queued on the host: never sent
    assert received.count("TP") < traj.t_s.size
    assert emulator.executions == []
    np.testing.assert_allclose(emulator.driver.state.q, ASEA.q_home)
    assert driver.state.estopped


async def test_estop_during_a_move_reports_estop_and_blocks_until_reset(driver, emulator):
    slow = plan_joint_move(driver.state.q, ASEA.q_ready, speed=0.1)
    task = asyncio.create_task(driver.move(slow))
    async with asyncio.timeout(2.0):
        while not driver.state.moving:
            await asyncio.sleep(0.005)
    await driver.estop()
    report = await task
    assert not report.completed and report.reason == "estop"
    with pytest.raises(RobotBusy):
        await driver.move(plan_joint_move(driver.state.q, ASEA.q_home))
    await driver.reset()
    assert not driver.state.estopped
    report = await driver.move(plan_joint_move(driver.state.q, ASEA.q_home))
    assert report.completed
    assert emulator.executed_mids() == [1, 2]


async def test_stop_ends_a_move_with_reason_stopped(driver):
    task = asyncio.create_task(driver.move_joints(ASEA.q_ready, speed=0.1))
    async with asyncio.timeout(2.0):
        while not driver.state.moving:
            await asyncio.sleep(0.005)
    await driver.stop()
    report = await task
    assert not report.completed and report.reason == "stopped"
    assert report.final_error_rad > 0


async def test_cancelling_a_move_stops_the_arm(driver, emulator):
    task = asyncio.create_task(driver.move_joints(ASEA.q_ready, speed=0.1))
    async with asyncio.timeout(2.0):
        while not driver.state.moving:
            await asyncio.sleep(0.005)
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task
    async with asyncio.timeout(2.0):
        while emulator.driver.state.moving:
            await asyncio.sleep(0.01)
    assert "STOP" in [c.VERB for c in emulator.received]
