"""Bug: leaving a ``CellRuntime`` could wait forever in ``IndexSync.stop()`` (seen in the
fault campaign: the process idle, the index-sync task "cancelling" yet still polling).
On Python 3.11 ``asyncio.wait_for`` returns the result, and loses the cancellation, when the
awaited sync finishes in the loop iteration in which ``stop()`` cancels the task; the loop
went on and ``stop()`` awaited it for ever.  ``stop()`` now cancels until the task ends
(``backend.taskutil.cancel_and_wait``)."""

from __future__ import annotations

import asyncio

from backend.db.session import Database
from backend.recognition.index import LiveIndex
from backend.recognition.sync import IndexSync, SyncReport
from backend.taskutil import cancel_and_wait


def test_stop_ends_the_task_when_the_cancel_meets_a_finishing_sync(tmp_path):
    async def main() -> None:
        db = Database(f"sqlite+aiosqlite:///{tmp_path / 'x.db'}")
        sync = IndexSync(db, LiveIndex(method="orb", max_features=50), poll_s=0.05)
        stopping: list[asyncio.Task[None]] = []

        async def sync_once() -> SyncReport:
            if not stopping:  # stop() is called as this sync finishes
                stopping.append(asyncio.get_running_loop().create_task(sync.stop()))
            return SyncReport(False)

        sync.sync_once = sync_once  # type: ignore[method-assign]
        sync.start()
        try:
            while not stopping:
                await asyncio.sleep(0.01)
            await asyncio.wait_for(asyncio.shield(stopping[0]), 5.0)
        finally:
            if sync._task is not None:
                await cancel_and_wait(sync._task)
            await db.dispose()

    asyncio.run(main())


def test_cancel_and_wait_of_a_finished_or_failing_task():
    async def main() -> None:
        async def boom() -> None:
            raise RuntimeError("the task's own failure is its owner's business")

        t = asyncio.get_running_loop().create_task(boom())
        await asyncio.sleep(0)
        try:
            await cancel_and_wait(t)
        except RuntimeError:
            pass
        else:
            raise AssertionError("a failure of the task is not hidden")

        async def forever() -> None:
            await asyncio.Event().wait()

        t = asyncio.get_running_loop().create_task(forever())
        await cancel_and_wait(t, every_s=0.1)
        assert t.cancelled()

    asyncio.run(main())
