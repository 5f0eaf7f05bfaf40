"""Regression: two motion jobs started in the same event-loop tick were both accepted (the
motion lock was only taken when the first job's task ran).  The arm is now reserved inside
``JobManager.start``: the second is refused with RobotBusy, which the API answers with 409."""

from __future__ import annotations

import asyncio

import pytest

from backend.api.errors import status_of
from backend.jobs import JobManager
from robot.errors import RobotBusy
from tests.utils.cells import ideal_cell

Q_A = [0.3, 1.45, -1.65, -0.2, 0.4]


async def _idle(job):
    await asyncio.sleep(0.05)
    return {}


async def test_second_motion_job_in_the_same_tick_is_refused():
    jobs = JobManager()
    first = jobs.start("move", _idle, motion=True)
    with pytest.raises(RobotBusy, match=f"job {first.id} \\(move\\)"):
        jobs.start("move", _idle, motion=True)  # no await in between: the same tick
    other = jobs.start("solve", _idle)  # jobs that do not move are not held up
    await jobs.wait(first)
    await jobs.wait(other)
    assert len(jobs.list()) == 2
    jobs.start("move", _idle, motion=True)  # the reservation went with the first job
    await jobs.shutdown()


async def test_cell_moves_in_the_same_tick(settings):
    cell, _, _ = ideal_cell(settings)
    await cell.start()
    try:
        job = cell.home(speed=1.0)
        with pytest.raises(RobotBusy) as info:
            cell.move_joints(Q_A, speed=1.0)
        assert status_of(info.value) == 409 and info.value.code == "robot_busy"
        await cell.jobs.wait(job)
        assert job.state.value == "done"
    finally:
        await cell.stop()


async def test_a_job_cancelled_before_it_ran_gives_the_arm_back():
    jobs = JobManager()
    job = jobs.start("move", _idle, motion=True)
    job.task.cancel()  # before its first step: its coroutine never runs
    await asyncio.sleep(0)
    await asyncio.sleep(0)
    assert job.state.value == "cancelled" and jobs.arm_holder is None
    jobs.start("move", _idle, motion=True)
    await jobs.shutdown()


def test_api_answers_409_for_the_second_move(client, headers):
    slow = client.post("/api/robot/move", json={"joints": Q_A, "speed": 0.05},
                       headers=headers["operator"])  # fmt: skip
    assert slow.status_code == 202
    r = client.post("/api/robot/home", headers=headers["operator"])
    assert r.status_code == 409
    assert r.json()["error"] == "robot_busy"
    assert slow.json()["job"]["id"] in r.json()["detail"]
    client.post("/api/robot/stop", headers=headers["operator"])
