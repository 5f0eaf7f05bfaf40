"""Timeouts, partial lines, garbage and a noisy line, on a real pseudo-terminal."""

import asyncio

import pytest

from robot.drivers.serial import FaultConfig
from robot.drivers.serial import frames as fr
from robot.errors import CommandTimeout
from robot.model import ASEA
from robot.trajectory import plan_joint_move


async def test_silent_controller_times_out_then_the_link_is_reopened(driver, emulator):
    emulator.fault = FaultConfig(silent=True)
    with pytest.raises(CommandTimeout, match="PING"):
        await driver.ping()
    async with asyncio.timeout(3.0):  # silence_timeout_s = 0.6: declared down
        while driver.state.connected:
            await asyncio.sleep(0.02)
    assert "silent" in driver.state.fault
    emulator.fault = FaultConfig()
    async with asyncio.timeout(5.0):
        while not driver.state.connected:
            await asyncio.sleep(0.02)
    assert await driver.ping() > 0
    assert driver.outages == 1


async def test_every_command_has_a_timeout(emulator, make_driver):
    driver = make_driver(emulator.path, silence_timeout_s=30.0, command_timeout_s=0.3)
    await driver.connect()
    emulator.fault = FaultConfig(silent=True)
    for call in (driver.stop, driver.reset, driver.query_limits, driver.ping):
        with pytest.raises(CommandTimeout):
            async with asyncio.timeout(2.0):  # the driver's own timeout fires first
                await call()
    # A motion command that may have arrived is not raised but reported, outcome unknown.
    report = await driver.move_joints(ASEA.q_ready, speed=1.0)
    assert not report.completed and "outcome" in report.reason
    assert emulator.executions == []


async def test_partial_lines_are_joined(raw_host):
    wire = fr.encode(fr.Hello(1, "00C0FFEE"))
    for i in range(0, len(wire), 3):  # three bytes at a time, with pauses
        raw_host.write(wire[i : i + 3])
        await asyncio.sleep(0.002)
    assert isinstance(await raw_host.reply(1), fr.Ack)


async def test_garbage_and_overlong_lines_are_dropped_and_the_link_recovers(raw_host, emulator):
    raw_host.write(b"\x00\xff\x13 noise without a newline " * 20)  # > 256 bytes, no LF
    raw_host.write(b"\nC 1 PING*0000\n")  # bad checksum
    raw_host.write(b"C 2 PING\n")  # no checksum at all
    raw_host.write(fr.encode(fr.Hello(3, "00C0FFEE")))
    assert isinstance(await raw_host.reply(3), fr.Ack)
    assert raw_host.replies(1) == [] and raw_host.replies(2) == []
    assert emulator.stats.rx_rejected == 2


async def test_checksummed_frame_with_bad_arguments_gets_nak_syntax(raw_host):
    from robot.drivers.serial.framing import seal

    raw_host.write(fr.encode(fr.Hello(1, "00C0FFEE")))
    await raw_host.reply(1)
    raw_host.write(seal("C 2 MOVE 1 0 0 0 0 0 Z 1"))
    nak = await raw_host.reply(2)
    assert isinstance(nak, fr.Nak) and nak.code == "SYNTAX"


async def test_moves_survive_a_noisy_line_and_run_exactly_once(make_driver, emulator):
    # This test is about exactly-once execution, not latency: a command timeout of 3 s (the
    # FAST fixture's 1 s is for the timeout tests) keeps a starved CI machine from turning
    # a slow resend round into a failed upload.
    driver = make_driver(emulator.path, command_timeout_s=3.0)
    await driver.connect()
    assert driver.state.connected
    emulator.fault = FaultConfig(
        drop_p=0.04, corrupt_p=0.04, truncate_p=0.03, garbage_p=0.04, delay_p=0.03, delay_s=0.03
    )
    goals = [ASEA.q_ready, ASEA.q_home] * 3
    for goal in goals:
        traj = plan_joint_move(driver.state.q, goal, rate_hz=30.0)
        report = await driver.move(traj)
        assert report.completed, report
    emulator.fault = FaultConfig()
    assert emulator.executed_mids() == list(range(1, len(goals) + 1))
    injected = emulator.stats.faults
    assert injected.on_commands > 10
    assert driver.stats["rejected_lines"] > 0 and driver.stats["resends"] > 0
    assert emulator.stats.rx_rejected > 0
