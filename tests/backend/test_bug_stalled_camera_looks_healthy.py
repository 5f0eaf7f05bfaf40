"""Bug (fault campaign): a camera whose ``grab()`` never returned left the acquisition task
hung with its status still ``ok`` -- the cell kept moving to viewpoints for pictures that
never came.  Now a grab longer than ``GRAB_TIMEOUT_S`` is a ``camera stalled`` error shown
in the status, ``look`` refuses to move while the camera fails, and frames come back by
themselves when the camera does."""

from __future__ import annotations

import asyncio
import random
import time

import pytest

from backend.cell import CameraFeed, camera
from robot.backoff import Backoff
from tests.utils.cells import ScriptedCamera


async def _until(pred, timeout_s=5.0):
    t0 = time.monotonic()
    while not pred():
        if time.monotonic() - t0 > timeout_s:
            raise AssertionError("condition not reached")
        await asyncio.sleep(0.005)


async def test_a_hanging_grab_is_reported_as_stalled_and_recovers(monkeypatch):
    monkeypatch.setattr(camera, "GRAB_TIMEOUT_S", 0.2)
    cam = ScriptedCamera()
    gate = asyncio.Event()
    inner = cam.grab

    async def grab():
        if not gate.is_set():
            await gate.wait()  # the stall: no frame, no error
        return await inner()

    feed = CameraFeed(cam, fps=100.0, idle_fps=100.0,
                      backoff=Backoff(initial_s=0.05, max_s=0.05, rng=random.Random(2)))  # fmt: skip
    feed.start()
    try:
        await _until(lambda: feed.status().ok)
        cam.grab = grab
        await _until(lambda: not feed.status().ok, timeout_s=3.0)
        assert "stalled" in feed.status().error and feed.failing
        t = time.monotonic()
        with pytest.raises(Exception, match="stalled"):
            await feed.next_frame(after=t, timeout_s=0.5)
        gate.set()
        await _until(lambda: feed.status().ok, timeout_s=3.0)
        frame = await feed.next_frame(after=time.monotonic(), timeout_s=2.0)
        assert frame is not None and feed.failing == ""
    finally:
        await feed.stop()
