"""Bug (CI, stop 20): when the host's own event loop was held up for longer than the silence
timeout (a starved machine; in a cell, the GIL behind a long computation), the first
heartbeat after it found nothing received "for 0.6 s" and dropped a healthy link, failing the
move in progress.  No ping had gone out in that time, so nothing could have come back.
Silence is now counted in the host's running time."""

import asyncio
import time

from robot.drivers.serial import FaultConfig
from robot.model import ASEA


async def test_a_stalled_host_keeps_a_live_link_and_its_move(driver, emulator):
    await asyncio.sleep(0.3)  # heartbeats flowing
    task = asyncio.create_task(driver.move_joints(ASEA.q_ready, speed=0.5))
    async with asyncio.timeout(5.0):
        while not driver.state.moving:
            await asyncio.sleep(0.005)
    # The whole loop held for longer than the silence timeout (0.6 s) and shorter than the
    # emulated controller's watchdog (1 s; a longer stall rightly stops the arm).
    time.sleep(0.8)
    report = await task
    assert report.completed, report
    assert driver.state.connected and driver.outages == 0
    assert await driver.ping() > 0


async def test_a_silent_controller_is_still_declared_down_after_a_stall(driver, emulator):
    time.sleep(1.0)  # a stall first: its time is not counted ...
    emulator.fault = FaultConfig(silent=True)  # ... but the controller's own silence is
    t0 = time.monotonic()
    async with asyncio.timeout(5.0):
        while driver.state.connected:
            await asyncio.sleep(0.02)
    assert "silent" in driver.state.fault
    assert time.monotonic() - t0 >= 0.5  # counted from after the stall, not from before it
