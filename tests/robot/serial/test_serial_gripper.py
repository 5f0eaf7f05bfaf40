"""The gripper command over the serial line: frames, the emulator, SerialDriver.grip()."""

from __future__ import annotations

import asyncio

import pytest

from robot.drivers.serial import frames as fr
from robot.drivers.serial.faults import FaultConfig
from robot.drivers.serial.payloads import ArmSnapshot
from robot.errors import CommandTimeout, ProtocolError, RobotBusy


def test_grip_frames_round_trip():
    for on in (True, False):
        cmd = fr.Grip(12, on)
        wire = fr.encode(cmd)
        assert wire.startswith(b"C 12 GRIP " + (b"1" if on else b"0") + b"*")
        assert fr.decode(wire.rstrip(b"\n")) == cmd
    assert fr.Grip.parse_reply(["1", "0"]) == (True, False)
    for bad in (["2"], ["on"], [], ["1", "1"]):
        body = " ".join(["C", "3", "GRIP", *bad])
        with pytest.raises(ProtocolError) as exc:
            fr.decode_body(body)
        assert exc.value.seq == 3
    with pytest.raises(ProtocolError):
        fr.Grip.parse_reply(["1"])


def test_state_flags_carry_the_gripper():
    snap = ArmSnapshot(5, (0.0,) * 5, (0.0,) * 5, True, False, 1, "RUNNING", "", True, True)
    args = snap.to_args()
    assert args[11] == "MGH"
    assert ArmSnapshot.from_args(args) == snap
    plain = ArmSnapshot(5, (0.0,) * 5, (0.0,) * 5, False, False, 0, "NONE")
    assert plain.to_args()[11] == "-"
    assert not ArmSnapshot.from_args(plain.to_args()).gripper_on
    args[11] = "HG"  # letters out of order
    with pytest.raises(ProtocolError, match="MEGH"):
        ArmSnapshot.from_args(args)


async def _until(pred, timeout_s=2.0):
    async with asyncio.timeout(timeout_s):
        while not pred():
            await asyncio.sleep(0.01)


async def test_driver_grips_and_releases_over_a_pseudo_terminal(driver, emulator):
    assert not driver.state.gripper_on
    report = await driver.grip(True)
    assert report.on and report.holding and report.detail == "part held"
    assert emulator.driver.state.gripper_on
    # The reply refreshed the state; the stream keeps showing it.
    assert driver.state.gripper_on and driver.state.holding
    await asyncio.sleep(0.1)
    assert driver.state.gripper_on
    report = await driver.grip(False)
    assert not report.on and not report.holding
    await _until(lambda: not driver.state.gripper_on)
    assert not emulator.driver.state.gripper_on
    assert driver.state.as_dict()["gripper_on"] is False


async def test_grip_is_refused_during_an_emergency_stop(driver, emulator):
    await driver.grip(True)
    await driver.estop()
    with pytest.raises(RobotBusy, match="ESTOP"):
        await driver.grip(False)
    assert emulator.driver.state.gripper_on  # the part is not dropped by the stop
    await driver.reset()
    assert not (await driver.grip(False)).on


async def test_grip_has_a_timeout(emulator, make_driver):
    driver = make_driver(emulator.path, silence_timeout_s=30.0, command_timeout_s=0.3)
    await driver.connect()
    emulator.fault = FaultConfig(silent=True)
    with pytest.raises(CommandTimeout):
        async with asyncio.timeout(2.0):  # the driver's own timeout fires first
            await driver.grip(True)


async def test_grip_takes_a_bool_only(driver):
    for bad in (1, 0, "1", None):
        with pytest.raises(ValueError, match="True or False"):
            await driver.grip(bad)  # type: ignore[arg-type]


async def test_raw_grip_command_and_reply(raw_host):
    raw_host.send(fr.Hello(1, "00C0FFEE"))
    await raw_host.reply(1)
    raw_host.send(fr.Grip(2, True))
    ack = await raw_host.reply(2)
    assert isinstance(ack, fr.Ack) and ack.verb == "GRIP" and ack.args == ("1", "1")
    raw_host.send(fr.Grip(3, False))
    ack = await raw_host.reply(3)
    assert ack.args == ("0", "0")
