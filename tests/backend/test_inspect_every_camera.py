"""``inspect once`` without the simulator, on each camera kind and through the serial link:
the folder camera on real images (COIL-20 from the data directory), an OpenCV camera on a
video file this test writes (streamed, and replayed one frame per look), and the serial
controller's emulator on a pseudo-terminal in front of the ideal arm.  Models are uploaded
over REST; each inspection is started and read back over REST with a user's token."""

from __future__ import annotations

import asyncio
import functools
import threading
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest
from fastapi.testclient import TestClient

import robot.drivers.serial
from backend.app import create_app
from robot.drivers.ideal import IdealDriver
from robot.drivers.serial.emulator import Emulator
from tests.utils.factories import make_settings, make_tokens, migrate
from tests.utils.recorded import coil_dir, coil_file, link_sequence, upload_views, wait_job

Headers = dict[str, dict[str, str]]


def _cell(settings) -> tuple[TestClient, Headers]:
    migrate(settings)
    tokens = make_tokens(settings)
    return TestClient(create_app(settings)), {
        role: {"Authorization": f"Bearer {tok}"} for role, tok in tokens.items()
    }


def _train(client: TestClient, h: Headers, coil: Path) -> None:
    for obj in (1, 2):
        r = client.post("/api/models", json={"name": f"obj{obj}", "kind": "2d", "threshold": 0.15},
                        headers=h["engineer"])  # fmt: skip
        assert r.status_code == 201, r.text
        r = upload_views(client, h["engineer"], r.json()["id"],
                         [coil_file(coil, obj, k) for k in range(0, 72, 4)])  # fmt: skip
        assert r.status_code == 201, r.text


def _inspect_once(client: TestClient, h: Headers) -> dict:
    r = client.post("/api/inspections", json={"policy": "top-only"}, headers=h["operator"])
    assert r.status_code == 202, r.text
    job = wait_job(client, h["viewer"], r.json()["job"]["id"])
    assert job["state"] == "done", job
    assert "uncalibrated" in job["params"]["camera_model"]
    r = client.get(f"/api/inspections/{job['result']['inspection_id']}", headers=h["viewer"])
    assert r.status_code == 200, r.text
    return r.json()


def _write_video(path: Path, frames: list[np.ndarray]) -> Path:
    h, w = frames[0].shape[:2]
    out = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (w, h))
    assert out.isOpened(), "OpenCV cannot write MJPG video here"
    for f in frames:
        out.write(cv2.cvtColor(f, cv2.COLOR_RGB2BGR))
    out.release()
    return path


def _rgb(path: Path) -> np.ndarray:
    return cv2.cvtColor(cv2.imread(str(path)), cv2.COLOR_BGR2RGB)


def test_folder_camera_on_real_images(tmp_path, data_dir):
    coil = coil_dir(data_dir)
    folder = link_sequence(tmp_path / "camera", [coil_file(coil, 2, 30)])
    client, h = _cell(make_settings(tmp_path, camera_folder=folder, data_dir=data_dir))
    with client:
        _train(client, h, coil)
        row = _inspect_once(client, h)
    assert row["decision"] == "recognized" and row["model"] == "obj2", row["reason"]


def test_opencv_camera_on_a_video_file(tmp_path, data_dir):
    coil = coil_dir(data_dir)
    video = _write_video(tmp_path / "belt.avi", [_rgb(coil_file(coil, 1, 6))] * 5)
    client, h = _cell(make_settings(tmp_path, camera="opencv", camera_device=str(video),
                                    data_dir=data_dir))  # fmt: skip
    with client:
        _train(client, h, coil)
        row = _inspect_once(client, h)
    assert row["decision"] == "recognized" and row["model"] == "obj1", row["reason"]


def test_video_file_replays_one_frame_per_look(tmp_path, data_dir):
    coil = coil_dir(data_dir)
    shots = [(1, 6), (13, 0), (2, 30)]
    video = _write_video(tmp_path / "rec.avi", [_rgb(coil_file(coil, o, k)) for o, k in shots])
    client, h = _cell(make_settings(tmp_path, camera="opencv", camera_device=str(video),
                                    camera_replay="look", data_dir=data_dir))  # fmt: skip
    with client:
        _train(client, h, coil)
        got = [_inspect_once(client, h) for _ in shots]
    assert [(r["decision"], r["model"]) for r in got] == [
        ("recognized", "obj1"), ("unknown", None), ("recognized", "obj2"),
    ]  # fmt: skip


@pytest.fixture
def emulated_controller(tmp_path, monkeypatch) -> Iterator[str]:
    """The serial controller's emulator on a pseudo-terminal (own thread and event loop)
    in front of the ideal arm; yields the link's path."""
    link = str(tmp_path / "robot-tty")
    ready = threading.Event()
    loop = asyncio.new_event_loop()
    box: dict = {}

    async def serve() -> None:
        box["stop"] = asyncio.Event()
        arm = IdealDriver(time_scale=20.0)
        await arm.connect()
        emu = Emulator(arm, link=link, watchdog_s=10.0)
        try:
            await emu.start()
            ready.set()
            await box["stop"].wait()
        finally:
            await emu.close()
            await arm.close()

    thread = threading.Thread(target=lambda: loop.run_until_complete(serve()), daemon=True)
    thread.start()
    assert ready.wait(60), "emulator did not start"
    # One process plays the controller and the backend on a shared machine: allow the
    # controller longer silences than a real line would.
    monkeypatch.setattr(
        robot.drivers.serial, "SerialDriver",
        functools.partial(robot.drivers.serial.SerialDriver, silence_timeout_s=10.0,
                          command_timeout_s=10.0, connect_timeout_s=10.0),
    )  # fmt: skip
    yield link
    loop.call_soon_threadsafe(box["stop"].set)
    thread.join(30)


def test_serial_driver_through_the_emulator(tmp_path, data_dir, emulated_controller):
    coil = coil_dir(data_dir)
    folder = link_sequence(tmp_path / "camera", [coil_file(coil, 1, 10)])
    client, h = _cell(make_settings(tmp_path, driver="serial", serial_port=emulated_controller,
                                    camera_folder=folder, data_dir=data_dir))  # fmt: skip
    with client:
        status = client.get("/api/status", headers=h["operator"]).json()
        assert status["driver"]["name"] == "serial" and status["driver"]["connected"] is True
        _train(client, h, coil)
        row = _inspect_once(client, h)
    assert row["decision"] == "recognized" and row["model"] == "obj1", row["reason"]
    assert row["durations"]["move"] > 0.0  # the arm went to the top view over the link
