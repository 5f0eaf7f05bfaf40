"""Regression: the camera feed could not be stopped (``cell.stop()`` hung for ever).

The feed wrapped each grab in ``asyncio.wait_for``; on Python 3.11 a cancel that lands as the
wrapped grab completes is swallowed, so the acquisition loop went on and ``stop()`` waited
for it without end (the e-stop conveyor test hung in ``cell.stop()``).  With a camera whose
grab returns at once (the race is then at every frame) the feed must stop, every time.
"""

from __future__ import annotations

import asyncio

from backend.cell.camera import CameraFeed
from tests.utils.cells import ScriptedCamera


async def test_feed_stops_every_time_with_an_instant_camera():
    for i in range(30):
        cam = ScriptedCamera()
        feed = CameraFeed(cam, fps=1000.0, idle_fps=1000.0)
        feed.start()
        feed.note_demand()
        await asyncio.sleep(0.002 * (i % 7))  # cancel at different points of the loop
        await asyncio.wait_for(feed.stop(), 5.0)
        assert not feed.running, f"feed still running after stop, attempt {i}"
