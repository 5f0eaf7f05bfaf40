"""The emulator's entry points: run_emulator in-process, and a separate emulator process."""

import asyncio
import os
import signal
import sys
from pathlib import Path

from robot.drivers import IdealDriver
from robot.drivers.serial.emulator import run_emulator
from robot.model import ASEA
from robot.trajectory import plan_joint_move

REPO = Path(__file__).parents[3]


async def test_run_emulator_announces_the_path_and_serves_until_stopped(make_driver, tmp_path):
    paths: list[str] = []
    stop = asyncio.Event()
    link = str(tmp_path / "var" / "robot-tty")
    arm = IdealDriver(time_scale=20.0)
    server = asyncio.create_task(
        run_emulator(arm, link=link, rate_hz=100.0, announce=paths.append, stop=stop)
    )
    async with asyncio.timeout(3.0):
        while not paths:
            await asyncio.sleep(0.01)
    assert paths == [link] and os.path.islink(link)
    d = make_driver(link)
    await d.connect()
    assert (await d.move_joints(ASEA.q_ready, speed=1.0)).completed
    await d.close()
    stop.set()
    emu = await server
    assert emu.executed_mids() == [1]
    assert not os.path.lexists(link)  # the port is gone with the emulator
    assert not arm.state.connected


async def test_emulator_in_another_process(make_driver, tmp_path):
    link = str(tmp_path / "robot-tty")
    proc = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "robot.drivers.serial.emulator", "--link", link, "--time-scale", "20",
        cwd=REPO, stdout=asyncio.subprocess.PIPE,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )  # fmt: skip
    try:
        async with asyncio.timeout(20.0):
            first = (await proc.stdout.readline()).decode().strip()
        assert first == link
        d = make_driver(link)
        await d.connect()
        assert d.state.connected
        report = await d.move(plan_joint_move(d.state.q, ASEA.q_ready))
        assert report.completed
        await d.close()
    finally:
        proc.send_signal(signal.SIGTERM)
        async with asyncio.timeout(10.0):
            assert await proc.wait() == 0
    assert not os.path.lexists(link)
