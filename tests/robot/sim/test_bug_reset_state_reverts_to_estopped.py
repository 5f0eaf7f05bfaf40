"""Regression: after an e-stop and a reset, the driver's state said "e-stopped" again.

A state sample the physics thread queued onto the event loop before ``reset()`` was
published after the fresh state that ``reset()`` published, so for up to one sample period
the backend refused motion with "emergency stop is active" although the latch was clear.
"""

from __future__ import annotations

import asyncio

from robot.model import ASEA
from robot.sim import SimDriver, SimEngine


async def test_a_sample_taken_before_reset_does_not_bring_the_estop_back(engine: SimEngine):
    engine.set_joints(ASEA.q_home)
    driver = SimDriver(engine, time_scale=8.0)
    await driver.connect()
    try:
        await driver.estop()
        stale = engine.arm_state()  # what the physics thread saw while the latch was set
        assert stale.estopped
        await driver.reset()
        assert not driver.state.estopped
        driver._on_sample(stale)  # delivered late, as call_soon_threadsafe can
        await asyncio.sleep(0)  # let the loop run the queued callback
        await asyncio.sleep(0)
        assert not driver.state.estopped
    finally:
        await driver.reset()
        await driver.close()
