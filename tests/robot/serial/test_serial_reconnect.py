"""The port vanishes and returns: the supervisor reconnects, moves report what happened."""

import asyncio
import logging

import pytest

from robot.drivers import IdealDriver
from robot.drivers.serial.emulator import Emulator
from robot.errors import LinkDown
from robot.model import ASEA
from robot.trajectory import plan_joint_move


async def _until(pred, timeout_s=5.0):
    async with asyncio.timeout(timeout_s):
        while not pred():
            await asyncio.sleep(0.01)


@pytest.fixture
async def slow_cell(request, tmp_path):
    """An emulator whose arm runs in real time (moves last seconds).

    Its link watchdog is 1 s, or the value of ``@pytest.mark.watchdog(seconds)``.
    """
    mark = request.node.get_closest_marker("watchdog")
    arm = IdealDriver(time_scale=1.0, rate_hz=100.0)
    await arm.connect()
    emu = Emulator(arm, link=str(tmp_path / "tty"), watchdog_s=mark.args[0] if mark else 1.0)
    await emu.start()
    yield emu
    await emu.close()
    await arm.close()


@pytest.mark.watchdog(2.5)  # well above outage + reconnection, even on a loaded machine
async def test_short_outage_mid_move_the_move_completes_once(slow_cell, make_driver, caplog):
    emu = slow_cell
    d = make_driver(emu.path)
    await d.connect()
    seen = []

    async def watch():
        async for s in d.states():
            seen.append(s)

    w = asyncio.create_task(watch())
    caplog.set_level(logging.INFO, logger="robot.drivers.serial.driver")
    task = asyncio.create_task(d.move_joints(ASEA.q_ready, duration_s=1.5))
    await _until(lambda: d.state.moving)
    await emu.vanish(0.3)  # shorter than the controller's watchdog: the arm keeps going
    report = await task
    w.cancel()
    assert report.completed and report.reason == "done"
    assert emu.executed_mids() == [1]
    down = [s for s in seen if not s.connected]
    assert down and all(s.fault.startswith("disconnected") for s in down)
    assert seen[-1].connected and not seen[-1].moving
    warnings = [r for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1 and "unreachable" in warnings[0].getMessage()
    assert any("reachable again" in r.getMessage() for r in caplog.records)
    assert d.outages == 1


async def test_long_outage_mid_move_the_watchdog_stops_the_arm(slow_cell, make_driver):
    emu = slow_cell
    d = make_driver(emu.path)
    await d.connect()
    task = asyncio.create_task(d.move_joints(ASEA.q_ready, duration_s=3.0))
    await _until(lambda: d.state.moving)
    await emu.vanish(1.8)  # longer than the 1 s watchdog
    report = await task
    assert not report.completed and "watchdog" in report.reason
    assert emu.stats.watchdog_trips == 1
    # After reconnection the state stream resumes and the arm holds still.
    stamp = d.state.stamp_s
    await _until(lambda: d.state.stamp_s > stamp + 0.1)
    assert d.state.connected and not d.state.moving
    report = await d.move(plan_joint_move(d.state.q, ASEA.q_home, speed=1.0))
    assert report.completed
    assert emu.executed_mids() == [1, 2]


async def test_link_down_longer_than_the_grace_reports_disconnected(slow_cell, make_driver):
    emu = slow_cell
    d = make_driver(emu.path, reconnect_grace_s=0.3)
    await d.connect()
    task = asyncio.create_task(d.move_joints(ASEA.q_ready, duration_s=3.0))
    await _until(lambda: d.state.moving)
    outage = asyncio.create_task(emu.vanish(1.0))
    report = await task
    assert not report.completed and report.reason.startswith("disconnected")
    assert not d.state.connected
    with pytest.raises(LinkDown):
        await d.estop()  # cannot be delivered: says so instead of pretending
    await outage
    await _until(lambda: d.state.connected)


async def test_repeated_outages_each_logged_once_and_recovered(emulator, make_driver, caplog):
    d = make_driver(emulator.path)
    await d.connect()
    caplog.set_level(logging.WARNING, logger="robot.drivers.serial.driver")
    for _ in range(3):
        await emulator.vanish(0.25)
        await _until(lambda: d.state.connected)
        assert await d.ping() > 0
    assert d.outages == 3
    assert len([r for r in caplog.records if "unreachable" in r.getMessage()]) == 3
    report = await d.move_joints(ASEA.q_ready, speed=1.0)
    assert report.completed


async def test_a_restarted_controller_is_detected(ideal, make_driver, tmp_path):
    path = str(tmp_path / "tty")
    first = Emulator(ideal, link=path)
    await first.start()
    d = make_driver(path)
    await d.connect()
    boot = d.controller.boot_id
    task = asyncio.create_task(d.move_joints(ASEA.q_ready, duration_s=40.0))
    await _until(lambda: d.state.moving)
    await first.close()  # the controller dies mid-move (its arm stops)
    await _until(lambda: not d.state.connected)
    async with Emulator(ideal, link=path) as second:  # a new controller at the same path
        report = await task
        assert not report.completed and "restarted" in report.reason
        assert d.state.connected
        assert d.controller.boot_id == second.boot_id != boot and not d.controller.resumed
        report = await d.move(plan_joint_move(d.state.q, ASEA.q_ready, speed=1.0))
        assert report.completed and second.executed_mids() == [2]
