"""Stopping a background task for sure.

``task.cancel()`` followed by ``await task`` can wait forever on Python 3.11: when the
task is inside ``asyncio.wait_for`` and the awaited operation finishes in the same loop
iteration as the cancellation arrives, ``wait_for`` returns the result and the
cancellation is lost (CPython issue gh-86296, fixed by the rewrite of ``wait_for`` in
3.12); a supervised loop then simply goes on.  :func:`cancel_and_wait` cancels again until
the task has ended.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Awaitable, Coroutine
from typing import Any, TypeVar

T = TypeVar("T")

__all__ = ["BackgroundTasks", "cancel_and_wait", "work_for_waiters"]


async def cancel_and_wait(task: asyncio.Task[Any], *, every_s: float = 0.5) -> None:
    """Cancel ``task`` and wait for its end, cancelling again every ``every_s`` seconds
    while it is still running (a cancellation swallowed by ``wait_for``)."""
    if not 0.0 < float(every_s) <= 60.0:
        raise ValueError(f"every_s must be within (0, 60] s, got {every_s!r}")
    while not task.done():
        task.cancel()
        await asyncio.wait({task}, timeout=every_s)
    with contextlib.suppress(asyncio.CancelledError):
        task.result()


class BackgroundTasks:
    """A bounded set of background tasks that nobody awaits (a cache's re-reads ahead of
    expiry): at most ``limit`` run at once, :meth:`close` ends them, and none starts again
    until :meth:`open`.

    Parameters
    ----------
    limit : int
        Most tasks running at once, 1..1024.
    """

    def __init__(self, limit: int) -> None:
        if isinstance(limit, bool) or not isinstance(limit, int) or not 1 <= limit <= 1024:
            raise ValueError(f"limit must be an int within 1..1024, got {limit!r}")
        self.limit = limit
        #: Set by :meth:`close`, cleared by :meth:`open`: no task starts meanwhile.
        self.closed = False
        self._tasks: set[asyncio.Task[None]] = set()

    def __len__(self) -> int:
        """Tasks running (or ended but not yet reaped)."""
        return len(self._tasks)

    @property
    def tasks(self) -> frozenset[asyncio.Task[None]]:
        """The tasks held now."""
        return frozenset(self._tasks)

    def full(self) -> bool:
        """Whether :attr:`limit` tasks run (tasks that ended on a loop closed before their
        done callback ran are dropped first)."""
        if len(self._tasks) < self.limit:
            return False
        for task in [t for t in self._tasks if t.done()]:
            self._tasks.discard(task)
        return len(self._tasks) >= self.limit

    def spawn(
        self, loop: asyncio.AbstractEventLoop, coro: Coroutine[Any, Any, None], *, name: str
    ) -> asyncio.Task[None]:
        """Run ``coro`` as a task of ``loop``, held until it ends.  The caller checks
        :attr:`closed` and :meth:`full` first (it usually has more to check under the
        same conditions)."""
        task = loop.create_task(coro, name=name)
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)
        return task

    def open(self) -> None:
        """Let tasks start again after :meth:`close`."""
        self.closed = False

    async def close(self) -> None:
        """Start no task until :meth:`open`; cancel the running ones and wait for the end
        of those of the calling event loop (another loop's are only cancelled)."""
        self.closed = True
        loop = asyncio.get_running_loop()
        for task in list(self._tasks):
            if task.done():  # ended on a loop that closed before its done callback ran
                self._tasks.discard(task)
            elif task.get_loop() is loop:
                await cancel_and_wait(task)
            else:
                task.get_loop().call_soon_threadsafe(task.cancel)


async def work_for_waiters(future: asyncio.Future[Any], work: Awaitable[T]) -> T:
    """Await ``work`` on behalf of the requests waiting on ``future`` (a read shared while
    in flight): its exception is set on ``future`` (marked retrieved, so an unwaited future
    logs nothing) and raised again, its cancellation cancels ``future``; its value is
    returned for the caller to set on ``future`` in the form the waiters expect."""
    try:
        return await work
    except asyncio.CancelledError:
        future.cancel()
        raise
    except BaseException as exc:
        future.set_exception(exc)
        future.exception()
        raise
