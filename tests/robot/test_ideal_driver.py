import asyncio

import numpy as np
import pytest

from robot.drivers import IdealDriver, RobotDriver
from robot.errors import JointLimitError, RobotBusy
from robot.model import ASEA
from robot.trajectory import JointTrajectory, plan_joint_move


async def test_ideal_driver_follows_a_move_and_streams_states():
    d = IdealDriver(time_scale=10.0, rate_hz=100.0)
    assert isinstance(d, RobotDriver)
    await d.connect()
    seen = []

    async def watch():
        async for s in d.states():
            seen.append(s)

    w = asyncio.create_task(watch())
    report = await d.move(plan_joint_move(d.state.q, ASEA.q_ready))
    w.cancel()
    await d.close()
    assert report.completed and report.reason == "done"
    np.testing.assert_allclose(report.final_q, ASEA.q_ready, atol=1e-12)
    assert len(seen) > 3 and any(s.moving for s in seen)


async def test_stop_and_estop_end_a_move_early():
    d = IdealDriver(rate_hz=100.0)
    await d.connect()
    task = asyncio.create_task(d.move(plan_joint_move(d.state.q, ASEA.q_ready, speed=0.2)))
    await asyncio.sleep(0.1)
    await d.estop()
    report = await task
    assert not report.completed and report.reason == "estop"
    with pytest.raises(RobotBusy):
        await d.move(plan_joint_move(d.state.q, ASEA.q_home))
    await d.reset()
    report = await d.move(plan_joint_move(d.state.q, d.state.q))
    assert report.completed
    await d.close()


async def test_driver_refuses_trajectory_outside_limits():
    d = IdealDriver()
    await d.connect()
    q = np.tile(ASEA.q_home, (2, 1))
    q[1, 0] = 4.0
    bad = JointTrajectory(np.array([0.0, 1.0]), q, np.zeros((2, 5)))
    with pytest.raises(JointLimitError):
        await d.move(bad)
    assert d.state.q == tuple(ASEA.q_home)
    await d.close()
