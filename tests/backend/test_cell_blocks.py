"""The cell's building blocks: move_to, settle, look, next_frame, the event bus, and their
use from inside a motion job."""

from __future__ import annotations

import asyncio
import time

import numpy as np
import pytest

from backend.api.errors import status_of
from backend.cell import (
    JobProgress,
    JobState,
    MoveAborted,
    NotStill,
    PathBlocked,
    Pose,
)
from robot.collision import Box, CollisionWorld
from robot.errors import JointLimitError, RobotBusy, Unreachable
from robot.kinematics import fk
from robot.model import ASEA
from tests.utils.cells import ideal_cell
from vision.errors import CameraError

Q_A = np.array([0.3, 1.45, -1.65, -0.2, 0.4])


@pytest.fixture
async def cell(settings):
    c, _, _ = ideal_cell(settings.model_copy(update={"camera_fps": 50.0}))
    await c.start()
    yield c
    await c.stop()


async def test_move_to_joints_returns_the_completed_report(cell):
    report = await cell.move_to(Q_A, speed=1.0)
    assert report.completed and report.reason == "done"
    np.testing.assert_allclose(cell.driver.state.q, Q_A, atol=1e-9)


async def test_move_to_a_pose_solves_ik_and_arrives(cell):
    x, y, z, u, w = fk(Q_A)
    await cell.move_to(Pose(x, y, z, u, w, roll=0.4), speed=1.0)
    np.testing.assert_allclose(fk(np.asarray(cell.driver.state.q)), (x, y, z, u, w), atol=1e-6)


async def test_move_to_refuses_bad_targets_before_moving(cell):
    q0 = cell.driver.state.q
    with pytest.raises(JointLimitError, match="q2"):
        await cell.move_to([0.0, 3.0, -1.5, 0.0, 0.0])
    with pytest.raises(Unreachable):
        await cell.move_to(Pose(5.0, 0.0, 0.5, 0.0, -1.0))
    with pytest.raises(ValueError, match="speed must be in"):
        await cell.move_to(Q_A, speed=1e-6)
    with pytest.raises(ValueError, match="speed must be a number"):
        await cell.move_to(Q_A, speed=True)
    with pytest.raises(ValueError, match="joints must be 5 numbers"):
        await cell.move_to([True, False, True, False, True])
    with pytest.raises(ValueError, match="finite"):
        Pose(float("inf"), 0.0, 0.5, 0.0, -1.0)
    assert cell.driver.state.q == q0 and cell.jobs.arm_holder is None


async def test_move_to_is_collision_checked_along_the_path(cell):
    # A wall between home and Q_A: the flange passes through it on the straight joint path.
    mid = fk((np.asarray(ASEA.q_home) + Q_A) / 2)
    wall = Box("wall", (mid[0] - 0.05, mid[1] - 0.05, mid[2] - 0.05),
               (mid[0] + 0.05, mid[1] + 0.05, mid[2] + 0.05))  # fmt: skip
    q0 = cell.driver.state.q
    with pytest.raises(PathBlocked, match="wall") as info:
        await cell.move_to(Q_A, world=CollisionWorld((wall,)))
    assert info.value.contacts and status_of(info.value) == 422
    assert cell.driver.state.q == q0  # nothing moved
    await cell.move_to(Q_A, speed=1.0, world=CollisionWorld())  # no wall: fine


async def test_move_to_is_refused_while_another_holder_has_the_arm(cell):
    hold = asyncio.Event()

    async def body(job):
        await hold.wait()

    job = cell.jobs.start("hold", body, motion=True)
    with pytest.raises(RobotBusy, match=f"job {job.id} \\(hold\\)"):
        await cell.move_to(Q_A)
    hold.set()
    await cell.jobs.wait(job)
    await cell.move_to(Q_A, speed=1.0)  # free again


async def test_blocks_work_inside_a_motion_job_that_holds_the_arm(cell):
    async def body(job):
        await cell.move_to(Q_A, speed=1.0)
        job.report(0.5, "half way")
        frame = await cell.look(ASEA.q_home, speed=1.0)
        return {"q": list(frame.meta["q"]), "moving": frame.meta["moving"]}

    job = cell.jobs.start("tour", body, motion=True)
    with pytest.raises(RobotBusy):  # the job holds the arm: others are refused meanwhile
        cell.home()
    await cell.jobs.wait(job)
    assert job.state.value == "done", job.error
    np.testing.assert_allclose(job.result["q"], ASEA.q_home, atol=1e-9)
    assert job.result["moving"] is False


async def test_look_returns_a_frame_exposed_after_the_arm_stopped(cell):
    for q in (Q_A, ASEA.q_home, Q_A):
        t0 = time.monotonic()
        frame = await cell.look(q, speed=1.0, settle_s=0.0)
        assert frame.meta["moving"] is False  # exposed while still, never during the move
        np.testing.assert_allclose(frame.meta["q"], q, atol=1e-9)
        look = frame.meta["look"]
        assert frame.stamp_s > t0 + look["move_s"] + look["settle_s"]
        np.testing.assert_allclose(frame.robot_state.q, q, atol=1e-9)


async def test_settle_waits_until_still_and_is_bounded(cell):
    move = asyncio.create_task(cell.move_to(Q_A, speed=0.3))
    await asyncio.sleep(0.02)
    assert cell.driver.state.moving
    with pytest.raises(NotStill, match=r"not still after 0\.01 s"):
        await cell.settle(timeout_s=0.01)
    state = await cell.settle(timeout_s=30.0)
    assert not state.moving and max(abs(v) for v in state.qd) < 1e-3
    await move
    with pytest.raises(ValueError, match="timeout_s"):
        await cell.settle(timeout_s=1e9)


async def test_next_frame_waits_for_a_newer_frame(cell):
    first = await cell.next_frame(after=0.0)
    later = await cell.next_frame(after=first.stamp_s)
    assert later.stamp_s > first.stamp_s and later.index > first.index
    with pytest.raises(CameraError, match="no frame exposed after"):
        await cell.next_frame(after=time.monotonic() + 60.0, timeout_s=0.2)
    with pytest.raises(ValueError, match="after must be"):
        await cell.next_frame(after=float("nan"))


async def test_estop_aborts_a_move_to_and_refuses_the_next(cell):
    move = asyncio.create_task(cell.move_to(Q_A, speed=0.2))
    await asyncio.sleep(0.05)
    await cell.estop()
    with pytest.raises(MoveAborted, match="estop") as info:
        await move
    assert not info.value.report.completed
    with pytest.raises(RobotBusy, match="emergency stop"):
        await cell.move_to(ASEA.q_home)
    await cell.reset()
    await cell.move_to(ASEA.q_home, speed=1.0)


async def test_job_progress_and_state_go_on_the_bus(cell):
    sub = cell.bus.subscribe(JobState, JobProgress)

    async def body(job):
        for k in range(3):
            job.report((k + 1) / 3, f"step {k + 1}")
            await asyncio.sleep(0)
        return {"ok": True}

    job = cell.jobs.start("count", body)
    await cell.jobs.wait(job)
    events = []
    while (e := await sub.get(timeout_s=0.2)) is not None:
        events.append(e)
    sub.close()
    mine = [e for e in events if e.job_id == job.id]
    assert isinstance(mine[0], JobState) and mine[0].state == "running"
    assert [e.message for e in mine if isinstance(e, JobProgress)] == ["step 1", "step 2", "step 3"]
    assert isinstance(mine[-1], JobState) and mine[-1].state == "done"
    assert mine[-1].job["result"] == {"ok": True}
