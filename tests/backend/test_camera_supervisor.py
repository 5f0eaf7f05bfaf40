"""Camera acquisition under the supervisor: any exception is survived and shown in the
status, retries back off with jitter, JPEGs are cached by frame index; the OpenCV camera
(VISIONCELL_CAMERA=opencv) works end to end on a video file."""

from __future__ import annotations

import asyncio
import random
import time

import cv2
import numpy as np
import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from backend.cell import CameraFeed, CameraStatus, EventBus
from robot.backoff import Backoff
from tests.utils.cells import ScriptedCamera
from tests.utils.factories import make_settings, make_tokens, migrate


async def _until(pred, timeout_s=5.0):
    t0 = time.monotonic()
    while not pred():
        if time.monotonic() - t0 > timeout_s:
            raise AssertionError("condition not reached")
        await asyncio.sleep(0.005)


@pytest.mark.parametrize(
    "exc",
    [ZeroDivisionError("driver bug"), KeyError("lost"), RuntimeError("boom"), OSError(5, "io")],
)
async def test_any_exception_is_survived_and_reported(exc):
    cam = ScriptedCamera()
    bus = EventBus()
    statuses = []
    bus.add_listener(statuses.append, CameraStatus)
    feed = CameraFeed(
        cam, fps=200.0, idle_fps=200.0, publish=bus.publish,
        backoff=Backoff(initial_s=0.05, max_s=0.05, rng=random.Random(1)),
    )  # fmt: skip
    feed.start()
    try:
        await _until(lambda: feed.status().ok)
        cam.fail = [exc] * 3
        await _until(lambda: not feed.status().ok)
        st = feed.status()
        assert st.error.startswith(type(exc).__name__) and st.retries >= 1
        await _until(lambda: feed.status().ok, timeout_s=5.0)  # it came back by itself
        assert feed.running and cam.opens >= 2 and cam.closes >= 1
        assert feed.status().error == "" and feed.status().retries == 0
        seen = [(s.ok, s.error.split(":")[0]) for s in statuses]
        assert (
            seen[0] == (True, "") and (False, type(exc).__name__) in seen and seen[-1] == (True, "")
        )
    finally:
        await feed.stop()


async def test_failures_to_open_back_off_exponentially():
    cam = ScriptedCamera()
    cam.fail_open = [ValueError("no device")] * 4
    waits = []
    backoff = Backoff(initial_s=0.01, max_s=0.04, rng=random.Random(0))
    real = backoff.next_delay

    def record():
        w = real()
        waits.append(w)
        return w

    backoff.next_delay = record  # type: ignore[method-assign]
    feed = CameraFeed(cam, fps=100.0, idle_fps=100.0, backoff=backoff)
    feed.start()
    try:
        await _until(lambda: feed.status().ok)
        assert len(waits) == 4
        # 0.01, 0.02, 0.04, 0.04 (capped), each times a jitter factor in [0.5, 1]
        for w, base in zip(waits, (0.01, 0.02, 0.04, 0.04), strict=True):
            assert 0.5 * base <= w <= base
    finally:
        await feed.stop()


def test_backoff_validates_and_resets():
    b = Backoff(initial_s=1.0, max_s=8.0, jitter=(1.0, 1.0))
    assert [b.next_delay() for _ in range(5)] == [1.0, 2.0, 4.0, 8.0, 8.0]
    b.reset()
    assert b.next_delay() == 1.0 and b.attempts == 1
    for bad, match in (
        ({"initial_s": 0.0}, "initial_s"),
        ({"initial_s": float("nan")}, "initial_s"),
        ({"initial_s": True}, "initial_s"),
        ({"max_s": 0.1}, "max_s"),
        ({"jitter": (0.0, 1.0)}, "jitter"),
        ({"factor": 0.5}, "factor"),
    ):
        with pytest.raises(ValueError, match=match):
            Backoff(**bad)


async def test_jpeg_is_cached_by_frame_index():
    cam = ScriptedCamera()
    feed = CameraFeed(cam, fps=5.0, idle_fps=5.0)
    feed.start()
    try:
        await _until(lambda: feed.latest is not None)
        calls = []
        real = cv2.imencode
        try:
            cv2.imencode = lambda *a, **k: (calls.append(1), real(*a, **k))[1]  # type: ignore[assignment]
            first = feed.latest_jpeg()
            assert feed.latest_jpeg() is first and len(calls) == 1  # same frame: encoded once
            n = feed.status().frames
            await _until(lambda: feed.status().frames > n)
            second = feed.latest_jpeg()
            assert second != first and len(calls) == 2
        finally:
            cv2.imencode = real  # type: ignore[assignment]
        img = cv2.imdecode(np.frombuffer(second, np.uint8), cv2.IMREAD_COLOR)
        assert img.shape == (24, 32, 3)
        with pytest.raises(ValueError, match="quality"):
            feed.latest_jpeg(quality=0)
    finally:
        await feed.stop()


def _write_video(path, n=12, size=(96, 64)):
    w, h = size
    out = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (w, h))
    assert out.isOpened(), "OpenCV cannot write MJPG/AVI here"
    for k in range(n):
        img = np.zeros((h, w, 3), np.uint8)
        img[:, :, 2] = 255  # red in BGR
        cv2.putText(img, str(k), (5, 40), cv2.FONT_HERSHEY_SIMPLEX, 1.0, (255, 255, 255), 2)
        out.write(img)
    out.release()
    return path


def test_opencv_camera_end_to_end_on_a_video_file(tmp_path):
    video = _write_video(tmp_path / "cell.avi")
    s = make_settings(tmp_path, camera="opencv", camera_device=str(video), camera_fps=20.0)
    migrate(s)
    hdr = {"Authorization": f"Bearer {make_tokens(s)['viewer']}"}
    with TestClient(create_app(s)) as c:
        t0 = time.monotonic()
        while True:
            st = c.get("/api/camera/status", headers=hdr).json()
            if st["ok"] and st["frames"] > 15:  # more than the file holds: it loops
                break
            assert time.monotonic() - t0 < 30, st
            time.sleep(0.05)
        assert st["name"] == "opencv" and st["error"] == ""
        r = c.get("/api/camera/frame.jpg", headers=hdr)
        assert r.status_code == 200 and r.headers["content-type"] == "image/jpeg"
        img = cv2.imdecode(np.frombuffer(r.content, np.uint8), cv2.IMREAD_COLOR)
        assert img.shape == (64, 96, 3)
        b, _g, r_ = (float(img[..., k].mean()) for k in range(3))
        assert r_ > 150 and b < 110  # RGB inside, BGR again in the JPEG: still red


def test_opencv_camera_with_a_missing_device_reports_the_error(tmp_path):
    s = make_settings(tmp_path, camera="opencv", camera_device=str(tmp_path / "none.avi"))
    migrate(s)
    hdr = {"Authorization": f"Bearer {make_tokens(s)['viewer']}"}
    with TestClient(create_app(s)) as c:
        t0 = time.monotonic()
        while not (st := c.get("/api/camera/status", headers=hdr).json())["error"]:
            assert time.monotonic() - t0 < 10
            time.sleep(0.05)
        assert st["ok"] is False and "no such file" in st["error"]
        r = c.get("/api/camera/frame.jpg", headers=hdr)
        assert r.status_code == 503 and "no such file" in r.json()["detail"]
