"""The cell driven through the whole serial path: REST -> SerialDriver -> PTY -> emulator."""

from __future__ import annotations

import asyncio
import os
import signal
import subprocess
import sys
import threading
import time

import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from robot.drivers.ideal import IdealDriver
from robot.drivers.serial import SerialDriver
from robot.drivers.serial.emulator import run_emulator
from robot.model import ASEA
from tests.utils.factories import TEST_SECRET, make_settings, make_tokens, migrate


@pytest.fixture
def emulated_port(tmp_path):
    """An emulated controller (ideal arm, 10x real time) on its own loop and thread."""
    link = str(tmp_path / "robot-tty")
    ready = threading.Event()
    loop = asyncio.new_event_loop()
    stop: asyncio.Event | None = None

    async def serve() -> None:
        nonlocal stop
        stop = asyncio.Event()
        await run_emulator(
            IdealDriver(time_scale=10.0), link=link, announce=lambda _: ready.set(), stop=stop
        )

    thread = threading.Thread(target=loop.run_until_complete, args=(serve(),), daemon=True)
    thread.start()
    assert ready.wait(10), "emulator did not start"
    yield link
    loop.call_soon_threadsafe(stop.set)
    thread.join(10)


def test_rest_moves_the_arm_over_the_serial_link(tmp_path, emulated_port):
    settings = make_settings(tmp_path, driver="serial", serial_port=emulated_port)
    migrate(settings)
    tokens = make_tokens(settings)
    h = {"Authorization": f"Bearer {tokens['operator']}"}
    with TestClient(create_app(settings)) as client:
        status = client.get("/api/status", headers=h).json()
        assert status["driver"]["name"] == "serial" and status["driver"]["connected"] is True
        ready = [float(v) for v in ASEA.q_ready]
        r = client.post(
            "/api/robot/move?wait=true", json={"joints": ready, "speed": 1.0}, headers=h
        )
        assert r.status_code == 200, r.text
        assert r.json()["job"]["result"]["completed"] is True
        q = client.get("/api/robot/state", headers=h).json()["state"]["q"]
        assert q == pytest.approx(ready, abs=1e-3)
        bad = list(ready)
        bad[1] = 0.1
        r = client.post("/api/robot/move", json={"joints": bad}, headers=h)
        assert r.status_code == 422 and r.json()["error"] == "joint_limit"


async def test_cli_emulator_prints_its_path_and_serves(tmp_path):
    link = tmp_path / "tty"
    env = {**os.environ, "VISIONCELL_SECRET_KEY": TEST_SECRET}
    proc = subprocess.Popen(
        [sys.executable, "-m", "backend.cli", "emulator", "--link", str(link), "--rate", "50"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    try:
        first = await asyncio.to_thread(proc.stdout.readline)
        assert first.strip() == str(link)
        driver = SerialDriver(str(link))
        await driver.connect()
        try:
            assert driver.state.connected
            t0 = time.monotonic()
            while driver.state.q != tuple(ASEA.q_home) and time.monotonic() - t0 < 5:
                await asyncio.sleep(0.05)
            assert driver.state.q == pytest.approx(tuple(ASEA.q_home), abs=1e-6)
        finally:
            await driver.close()
    finally:
        proc.send_signal(signal.SIGINT)
        assert proc.wait(10) == 0
    assert not link.exists()  # a clean exit removes the link


def test_cli_emulator_names_a_bad_option(tmp_path):
    env = {**os.environ, "VISIONCELL_SECRET_KEY": TEST_SECRET}
    r = subprocess.run(
        [sys.executable, "-m", "backend.cli", "emulator", "--fault-drop", "1.5"],
        capture_output=True,
        text=True,
        env=env,
        timeout=60,
    )
    assert r.returncode == 2 and "drop_p must be a probability in [0, 1], got 1.5" in r.stderr
    r = subprocess.run(
        [sys.executable, "-m", "backend.cli", "emulator", "--driver", "serial"],
        capture_output=True,
        text=True,
        env=env,
        timeout=60,
    )
    assert r.returncode == 2 and "--driver must be 'ideal' or 'sim', got 'serial'" in r.stderr
