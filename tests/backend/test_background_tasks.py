"""``backend.taskutil.BackgroundTasks``: the bounded set of background re-reads the read and
sign-in caches keep (at most ``limit``, none after ``close`` until ``open``, ``close``
ends them)."""

from __future__ import annotations

import asyncio

import pytest

from backend.taskutil import BackgroundTasks


async def test_full_at_the_limit_and_free_again_when_a_task_ends() -> None:
    tasks = BackgroundTasks(2)
    release = asyncio.Event()
    loop = asyncio.get_running_loop()
    first = tasks.spawn(loop, release.wait(), name="a")  # type: ignore[arg-type]
    assert not tasks.full()
    tasks.spawn(loop, release.wait(), name="b")  # type: ignore[arg-type]
    assert tasks.full() and len(tasks) == 2 and first in tasks.tasks
    release.set()
    await asyncio.sleep(0)
    await asyncio.sleep(0)
    assert not tasks.full() and len(tasks) == 0


async def test_close_cancels_and_waits_then_open_lets_tasks_start() -> None:
    tasks = BackgroundTasks(4)
    loop = asyncio.get_running_loop()
    ended: list[str] = []

    async def forever() -> None:
        try:
            await asyncio.sleep(3600)
        finally:
            ended.append("cancelled")

    task = tasks.spawn(loop, forever(), name="forever")
    await asyncio.sleep(0)
    await tasks.close()
    assert task.cancelled() and ended == ["cancelled"]
    assert tasks.closed and len(tasks) == 0
    tasks.open()
    assert not tasks.closed


@pytest.mark.parametrize("limit", [0, 1025, True, 2.0, "4"])
def test_bad_limits_are_refused(limit: object) -> None:
    with pytest.raises(ValueError, match="limit"):
        BackgroundTasks(limit)  # type: ignore[arg-type]
