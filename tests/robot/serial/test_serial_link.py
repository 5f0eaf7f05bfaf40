"""Round trips between SerialDriver and the emulator over a real pseudo-terminal."""

import asyncio
import os

import numpy as np
import pytest

from robot.drivers import RobotDriver
from robot.drivers.serial.emulator import Emulator
from robot.errors import CommandRejected, DriverError, JointLimitError, LinkDown, RobotBusy
from robot.model import ASEA
from robot.trajectory import JointTrajectory, plan_joint_move


async def test_driver_round_trip_over_a_pseudo_terminal(driver, emulator):
    assert isinstance(driver, RobotDriver)
    assert os.path.islink(emulator.path)
    assert os.readlink(emulator.path).startswith("/dev/pts/")
    rtt = await driver.ping()
    assert rtt > 0
    assert driver.state.connected and not driver.state.moving
    np.testing.assert_allclose(driver.state.q, ASEA.q_home, atol=1e-6)
    assert driver.controller is not None and driver.controller.window == 8

    traj = plan_joint_move(driver.state.q, ASEA.q_ready)
    report = await driver.move(traj)
    assert report.completed and report.reason == "done"
    np.testing.assert_allclose(report.final_q, ASEA.q_ready, atol=2e-6)
    np.testing.assert_allclose(emulator.driver.state.q, ASEA.q_ready, atol=2e-6)
    assert emulator.executed_mids() == [1]
    assert emulator.executions[0].n_points == traj.t_s.size


async def test_limits_query_reports_the_controller_ranges(driver):
    limits = await driver.query_limits()
    np.testing.assert_allclose(limits.lower, ASEA.lower, atol=1e-6)
    np.testing.assert_allclose(limits.upper, ASEA.upper, atol=1e-6)
    np.testing.assert_allclose(limits.max_velocity, ASEA.max_velocity_rad_s, atol=1e-6)


async def test_state_stream_flows_and_follows_a_move(driver):
    seen = []

    async def watch():
        async for s in driver.states():
            seen.append(s)

    w = asyncio.create_task(watch())
    report = await driver.move_joints(ASEA.q_ready, speed=0.5)
    await asyncio.sleep(0.2)
    w.cancel()
    assert report.completed
    assert len(seen) > 5
    assert any(s.moving for s in seen) and not seen[-1].moving
    assert all(s.connected for s in seen)
    stamps = [s.stamp_s for s in seen]
    assert stamps == sorted(stamps)


async def test_controller_planned_move_by_duration(driver, emulator):
    report = await driver.move_joints(ASEA.q_ready, duration_s=3.0)
    assert report.completed and report.duration_s == pytest.approx(3.0, abs=1e-3)
    assert emulator.executions[-1].kind == "MOVE"
    with pytest.raises(CommandRejected, match="TRAJ"):
        await driver.move_joints(ASEA.q_home, duration_s=0.01)  # faster than the arm can
    assert len(emulator.executions) == 1


async def test_joint_limit_gate_runs_before_anything_is_sent(driver, emulator):
    q = np.tile(ASEA.q_home, (2, 1))
    q[1, 1] = 2.5  # q2 above 112.5 deg
    bad = JointTrajectory(np.array([0.0, 1.0]), q, np.zeros((2, 5)))
    before = len(emulator.received)
    with pytest.raises(JointLimitError):
        await driver.move(bad)
    with pytest.raises(JointLimitError):
        await driver.move_joints([0.0, 0.1, -1.5, 0.0, 0.0], speed=1.0)
    await asyncio.sleep(0.05)
    verbs = {c.VERB for c in list(emulator.received)[before:]}
    assert not verbs & {"TBEGIN", "TP", "RUN", "MOVE"}
    assert emulator.executions == []


async def test_controller_refuses_a_trajectory_that_starts_elsewhere(driver, emulator):
    traj = plan_joint_move(ASEA.q_ready, ASEA.q_home)  # the arm is at q_home
    with pytest.raises(DriverError, match="START"):
        await driver.move(traj)
    assert emulator.executions == []
    report = await driver.move(plan_joint_move(driver.state.q, ASEA.q_ready))
    assert report.completed


async def test_second_move_while_one_runs_is_refused(driver):
    slow = plan_joint_move(driver.state.q, ASEA.q_ready, speed=0.1)
    first = asyncio.create_task(driver.move(slow))
    await asyncio.sleep(0.05)
    with pytest.raises(RobotBusy):
        await driver.move(slow)
    assert (await first).completed


async def test_driver_waits_for_a_controller_that_appears_later(ideal, make_driver, tmp_path):
    path = str(tmp_path / "late-tty")
    d = make_driver(path, connect_timeout_s=0.2)
    await d.connect()  # nothing there yet: returns, keeps trying
    assert not d.state.connected and "disconnected" in d.state.fault
    with pytest.raises(LinkDown):
        await d.move_joints(ASEA.q_ready, speed=1.0)
    async with Emulator(ideal, link=path) as emu:
        async with asyncio.timeout(3.0):
            while not d.state.connected:
                await asyncio.sleep(0.02)
        report = await d.move_joints(ASEA.q_ready, speed=1.0)
        assert report.completed and emu.executed_mids() == [1]
