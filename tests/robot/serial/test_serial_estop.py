"""Emergency stop overtakes queued commands; stop and e-stop end moves like the ideal driver.

These tests are about order, not speed, so they hold on a loaded machine: the controller's
arm runs in real time (a slow move outlasts any stall of the process), the link's timeouts
and the controller's watchdog are far longer than a starved process's pauses, and every
wait on a condition is bounded by :data:`HANG_S` only to end a hang.
"""

import asyncio
from collections.abc import AsyncIterator

import numpy as np
import pytest

from robot.drivers import IdealDriver
from robot.drivers.serial import FaultConfig, SerialDriver
from robot.drivers.serial import frames as fr
from robot.drivers.serial.emulator import Emulator
from robot.errors import RobotBusy
from robot.model import ASEA
from robot.trajectory import plan_joint_move

#: Bounds a wait on a condition (a hang), never a claim about speed.
HANG_S = 60.0


@pytest.fixture
async def ideal() -> AsyncIterator[IdealDriver]:
    d = IdealDriver(time_scale=1.0, rate_hz=100.0)
    await d.connect()
    yield d
    await d.close()


@pytest.fixture
async def emulator(ideal: IdealDriver, tmp_path) -> AsyncIterator[Emulator]:
    emu = Emulator(ideal, link=str(tmp_path / "robot-tty"), rate_hz=50.0, seed=7, watchdog_s=30.0)
    await emu.start()
    yield emu
    await emu.close()


@pytest.fixture
async def driver(emulator: Emulator) -> AsyncIterator[SerialDriver]:
    # The conftest's quick timings, but no timeout a starved process could run into.
    d = SerialDriver(emulator.path, resend_after_s=0.05, command_timeout_s=30.0,
                     heartbeat_s=0.1, silence_timeout_s=30.0, connect_timeout_s=30.0,
                     reconnect_grace_s=3.0, backoff_initial_s=0.02, backoff_max_s=0.2,
                     seed=3)  # fmt: skip
    await d.connect()
    assert d.state.connected
    yield d
    await d.close()


async def test_estop_is_acknowledged_first_and_queued_motion_never_runs(driver, emulator):
    # A slow controller: commands pile up, and the upload takes many seconds, so the stop
    # overtakes it however late a loaded machine lets it go.
    emulator.fault = FaultConfig(process_delay_s=0.2)
    traj = plan_joint_move(driver.state.q, ASEA.q_ready, rate_hz=50.0)
    assert traj.t_s.size > 30
    upload = asyncio.create_task(driver.move(traj))
    async with asyncio.timeout(HANG_S):
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
    # A point still on its way (written before the stop, which goes out ahead of the
    # buffered bytes) reaches a move the stop discarded: refused too, as USED.
    i = next(k for k, r in enumerate(after) if isinstance(r, fr.Ack) and r.verb == "ESTOP")
    assert all(isinstance(r, fr.Ack) and r.verb == "TP" for r in after[:i]), after[:i]
    flushed = [r for r in after[i + 1 :] if isinstance(r, fr.Nak)]
    assert any(r.code == "ESTOP" for r in flushed), flushed  # queued on the controller
    assert all(r.code == "ESTOP" or (r.code == "USED" and "DISCARDED" in r.detail)
               for r in flushed), flushed  # fmt: skip
    assert not [r for r in after[i + 1 :] if isinstance(r, fr.Ack) and r.verb in ("TP", "RUN")]
    received = [c.VERB for c in emulator.received]
    assert "RUN" not in received  # queued on the host: never sent
    assert received.count("TP") < traj.t_s.size
    assert emulator.executions == []
    np.testing.assert_allclose(emulator.driver.state.q, ASEA.q_home)
    assert driver.state.estopped


async def test_estop_during_a_move_reports_estop_and_blocks_until_reset(driver, emulator):
    slow = plan_joint_move(driver.state.q, ASEA.q_ready, speed=0.1)
    task = asyncio.create_task(driver.move(slow))
    async with asyncio.timeout(HANG_S):
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
    async with asyncio.timeout(HANG_S):
        while not driver.state.moving:
            await asyncio.sleep(0.005)
    await driver.stop()
    report = await task
    assert not report.completed and report.reason == "stopped"
    assert report.final_error_rad > 0


async def test_cancelling_a_move_stops_the_arm(driver, emulator):
    task = asyncio.create_task(driver.move_joints(ASEA.q_ready, speed=0.1))
    async with asyncio.timeout(HANG_S):
        while not driver.state.moving:
            await asyncio.sleep(0.005)
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task
    async with asyncio.timeout(HANG_S):
        while emulator.driver.state.moving:
            await asyncio.sleep(0.01)
    assert "STOP" in [c.VERB for c in emulator.received]
