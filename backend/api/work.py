"""The heavy work of a request (:mod:`backend.heavy`), bound to its client.

``HeavyWorkDep`` gives a handler a :class:`RequestWork`: ``async with work.job() as job``
takes one of the runtime pool's job slots (503 ``busy`` with ``Retry-After`` when none
comes in time) and ``await job.run(fn, ...)`` runs a unit of work in the pool's threads.
While the handler runs, a watcher reads the request's ASGI channel for the client's
``http.disconnect`` (the body has been read by then); when it comes, the queued work is
dropped and the job ends with :class:`~backend.heavy.ClientGone` before its next unit.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator
from dataclasses import dataclass
from typing import Annotated

from fastapi import Depends, Request

from backend.api.deps import get_runtime
from backend.api.errors import ApiError
from backend.heavy import Busy, HeavyJob, HeavyPool

__all__ = ["HeavyWorkDep", "RequestWork", "request_work"]


@dataclass(frozen=True)
class RequestWork:
    """The pool and the "client gone" event of one request."""

    #: The runtime's pool.
    pool: HeavyPool
    #: Set when the client disconnects.
    gone: asyncio.Event

    @contextlib.asynccontextmanager
    async def job(self) -> AsyncIterator[HeavyJob]:
        """A job slot for this request (:meth:`HeavyPool.job`), 503 when the pool is busy."""
        try:
            cm = self.pool.job(cancel=self.gone)
            job = await cm.__aenter__()
        except Busy as exc:
            raise ApiError(
                503, exc.code, exc.detail, headers={"Retry-After": str(exc.retry_after_s)}
            ) from None
        try:
            yield job
        except BaseException as exc:
            if not await cm.__aexit__(type(exc), exc, exc.__traceback__):
                raise
        else:
            await cm.__aexit__(None, None, None)


async def _watch(request: Request, gone: asyncio.Event) -> None:
    while True:
        message = await request.receive()
        if message["type"] == "http.disconnect":
            gone.set()
            return


async def request_work(request: Request) -> AsyncIterator[RequestWork]:
    """Dependency: the request's :class:`RequestWork`, its disconnect watcher running until
    the handler returns."""
    pool: HeavyPool = get_runtime(request).heavy
    gone = asyncio.Event()
    watcher = asyncio.create_task(_watch(request, gone), name="client-gone watcher")
    try:
        yield RequestWork(pool, gone)
    finally:
        watcher.cancel()
        with contextlib.suppress(asyncio.CancelledError, Exception):
            await watcher


HeavyWorkDep = Annotated[RequestWork, Depends(request_work, scope="function")]
