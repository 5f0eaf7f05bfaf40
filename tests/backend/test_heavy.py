"""The heavy-work pool: job slots, the pixel budget, and cancellation when the client leaves.

Work that must stay running is held on a ``threading.Event``; waits only bound a hang.
"""

from __future__ import annotations

import asyncio
import threading

import pytest

from backend.api.errors import status_of
from backend.heavy import Busy, ClientGone, HeavyPool, PixelBudgetExceeded

HANG_S = 60.0


def held(started: threading.Event, release: threading.Event, ran: list[str], name: str):
    def work() -> str:
        started.set()
        assert release.wait(HANG_S), "never released"
        ran.append(name)
        return name

    return work


async def until(predicate, what: str) -> None:
    async with asyncio.timeout(HANG_S):
        while not predicate():
            await asyncio.sleep(0.01)


def test_a_unit_runs_in_a_pool_thread_and_returns_its_value():
    async def main():
        pool = HeavyPool(workers=1, max_jobs=1)
        try:
            async with pool.job() as job:
                name = await job.run(lambda: threading.current_thread().name)
            assert name.startswith("visioncell-heavy")
            assert pool.free_slots == 1 and pool.admitted == 1
        finally:
            pool.close()

    asyncio.run(main())


def test_a_full_pool_refuses_with_busy_after_its_wait():
    async def main():
        pool = HeavyPool(workers=1, max_jobs=1, admit_wait_s=0)
        try:
            async with pool.job():
                with pytest.raises(Busy) as info:
                    async with pool.job():
                        pass
                assert status_of(info.value) == 503 and info.value.retry_after_s >= 1
            async with pool.job():  # free again
                pass
            assert pool.refused == 1
        finally:
            pool.close()

    asyncio.run(main())


def test_a_client_that_leaves_while_waiting_for_a_slot_runs_nothing():
    async def main():
        pool = HeavyPool(workers=1, max_jobs=1, admit_wait_s=600)
        ran: list[str] = []
        try:
            async with pool.job():
                gone = asyncio.Event()

                async def second():
                    async with pool.job(cancel=gone) as job:
                        await job.run(ran.append, "second")

                task = asyncio.create_task(second())
                await asyncio.sleep(0)
                gone.set()
                with pytest.raises(ClientGone):
                    await asyncio.wait_for(task, HANG_S)
            assert ran == [] and pool.free_slots == 1
        finally:
            pool.close()

    asyncio.run(main())


def test_a_client_that_leaves_drops_its_queued_unit():
    async def main():
        pool = HeavyPool(workers=1, max_jobs=2)
        started, release, ran = threading.Event(), threading.Event(), []
        try:
            async with pool.job() as first:
                blocker = asyncio.create_task(first.run(held(started, release, ran, "first")))
                assert await asyncio.to_thread(started.wait, HANG_S)
                gone = asyncio.Event()
                async with pool.job(cancel=gone) as second:
                    queued = asyncio.create_task(second.run(ran.append, "second"))
                    await asyncio.sleep(0.05)
                    assert not queued.done()  # behind the first in the only thread
                    gone.set()
                    with pytest.raises(ClientGone):
                        await asyncio.wait_for(queued, HANG_S)
                    with pytest.raises(ClientGone):  # and no further unit starts
                        await second.run(ran.append, "third")
                release.set()
                assert await asyncio.wait_for(blocker, HANG_S) == "first"
            await until(lambda: pool.free_slots == 2, "slots back")
            await asyncio.sleep(0.05)
            assert ran == ["first"]  # the queued unit never ran
        finally:
            release.set()
            pool.close()

    asyncio.run(main())


def test_a_slot_is_held_until_a_running_unit_has_ended():
    async def main():
        pool = HeavyPool(workers=2, max_jobs=1, admit_wait_s=0)
        started, release, ran = threading.Event(), threading.Event(), []
        try:
            gone = asyncio.Event()
            with pytest.raises(ClientGone):
                async with pool.job(cancel=gone) as job:
                    task = asyncio.create_task(job.run(held(started, release, ran, "a")))
                    assert await asyncio.to_thread(started.wait, HANG_S)
                    gone.set()
                    await asyncio.wait_for(task, HANG_S)
            # the client left, but its unit still runs in a thread: its slot is not free
            assert pool.free_slots == 0
            with pytest.raises(Busy):
                async with pool.job():
                    pass
            release.set()
            await until(lambda: pool.free_slots == 1, "slot back")
            assert ran == ["a"]
        finally:
            release.set()
            pool.close()

    asyncio.run(main())


def test_the_pixel_budget_counts_every_image_of_a_job():
    async def main():
        pool = HeavyPool(max_pixels=1_000_000)
        try:
            async with pool.job() as job:
                job.take_pixels(800, 700, name="a.png")
                with pytest.raises(PixelBudgetExceeded, match=r"'b.png' \(800 x 700 px\)") as info:
                    job.take_pixels(800, 700, name="b.png")
                assert status_of(info.value) == 413
                job.take_pixels(500, 100)  # still within
            async with pool.job() as job:  # a new job has a budget of its own
                job.take_pixels(1000, 1000)
        finally:
            pool.close()

    asyncio.run(main())


@pytest.mark.parametrize(
    "kwargs",
    [{"workers": 0}, {"max_jobs": 0}, {"max_pixels": 0}, {"admit_wait_s": -1},
     {"admit_wait_s": float("nan")}, {"workers": True}],
)  # fmt: skip
def test_bad_pool_sizes_are_refused(kwargs):
    with pytest.raises(ValueError):
        HeavyPool(**kwargs)


def test_an_image_for_feature_extraction_has_a_smaller_cap():
    async def main():
        pool = HeavyPool(max_pixels=64_000_000, max_analysed_pixels=4_194_304)
        try:
            async with pool.job() as job:
                job.take_pixels(4000, 3000, name="cal.png")  # decoded only: within the budget
                with pytest.raises(PixelBudgetExceeded, match="at most 4194304 px"):
                    job.take_pixels(4000, 3000, name="view.png", analysed=True)
                job.take_pixels(2048, 2048, name="view.png", analysed=True)
        finally:
            pool.close()

    asyncio.run(main())
