"""A bounded worker pool for the CPU-heavy work of requests: decoding uploaded images,
extracting their features, detecting calibration targets, rendering report plots.

The event loop never runs this work itself: it answers ``/api/health``, the hot reads and
E-STOP while an upload is decoded.  Three bounds hold at once:

* **threads** -- :class:`HeavyPool` owns ``workers`` threads of its own (OpenCV releases
  the GIL while it decodes and extracts), apart from ``asyncio.to_thread``'s pool, so a
  burst of uploads cannot take the threads the cell's own work uses;
* **jobs** -- a request takes one of ``max_jobs`` slots for all of its heavy work
  (:meth:`HeavyPool.job`), waiting at most ``admit_wait_s`` for one; over that it is
  refused with :class:`Busy` (503 with ``Retry-After``), so the memory that decoded images
  and feature pyramids take is bounded by the slots, not by the clients;
* **pixels** -- a job may decode at most ``max_pixels`` pixels in all
  (:meth:`HeavyJob.take_pixels`, called with the size read from each file's header before
  it is decoded): a request of many large images is refused with 413 before the first
  decode that would pass the budget; an image whose features are to be extracted, or in
  which a calibration board is searched, may have at most ``max_analysed_pixels`` (SIFT's
  scale space takes about 230 bytes per pixel).

A job is cancellable: given the request's "client gone" event, work still queued when the
client leaves is dropped and the job stops with :class:`ClientGone` before its next unit
(a unit already running in a thread ends on its own; its slot is held until it has).
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
from collections.abc import AsyncIterator, Callable
from typing import Any, TypeVar

from vision.errors import VisionCellError

__all__ = [
    "DEFAULT_ADMIT_WAIT_S",
    "DEFAULT_MAX_ANALYSED_PIXELS",
    "DEFAULT_MAX_JOBS",
    "DEFAULT_MAX_PIXELS",
    "DEFAULT_WORKERS",
    "Busy",
    "ClientGone",
    "HeavyJob",
    "HeavyPool",
    "PixelBudgetExceeded",
]

T = TypeVar("T")

#: Threads of the pool.
DEFAULT_WORKERS = 1
#: Requests doing heavy work at once.
DEFAULT_MAX_JOBS = 2
#: Longest wait for a job slot before the request is refused (503), seconds.
DEFAULT_ADMIT_WAIT_S = 10.0
#: Decoded pixels one request may take in all (images and masks): 64 MP, about 192 MB as RGB.
DEFAULT_MAX_PIXELS = 64_000_000
#: Largest image features are extracted from or a calibration board searched in: 4 MP
#: (2048 x 2048; SIFT peaks near 1 GB on it; on 12 MP, SIFT near 2.8 GB and the board
#: search near 3 GB and two minutes).
DEFAULT_MAX_ANALYSED_PIXELS = 4_194_304


class Busy(VisionCellError):
    """Every job slot stayed taken for the whole admission wait."""

    code = "busy"

    def __init__(self, detail: str, *, retry_after_s: int) -> None:
        super().__init__(detail)
        #: Seconds a client should wait before trying again.
        self.retry_after_s = retry_after_s


class ClientGone(VisionCellError):
    """The client that asked for the work has disconnected; nobody reads the answer."""

    code = "client_closed_request"


class PixelBudgetExceeded(VisionCellError):
    """A request's images together have more pixels than one job may decode."""

    code = "too_large"


def _mark_retrieved(fut: asyncio.Future[Any]) -> None:
    # A result nobody waits for any more (the client left): read its exception so that
    # asyncio does not log "exception was never retrieved".
    if not fut.cancelled():
        fut.exception()


class HeavyJob:
    """One request's share of the pool: run work in it, count its decoded pixels.

    Made by :meth:`HeavyPool.job`; its slot is released when the ``async with`` block has
    ended *and* every unit it started has finished.
    """

    def __init__(self, pool: HeavyPool, cancel: asyncio.Event | None) -> None:
        self._pool = pool
        self._cancel = cancel
        self._loop = asyncio.get_running_loop()
        self._holders = 1  # the ``async with`` block, plus one per unit in the pool
        #: Pixels taken so far (:meth:`take_pixels`).
        self.pixels = 0

    @property
    def gone(self) -> bool:
        """Whether the client has left."""
        return self._cancel is not None and self._cancel.is_set()

    def check(self) -> None:
        """Raise :class:`ClientGone` if the client has left (between units of work)."""
        if self.gone:
            raise ClientGone("the client disconnected; its queued work was dropped")

    def take_pixels(
        self, width: int, height: int, *, name: str = "image", analysed: bool = False
    ) -> None:
        """Count an image of ``width`` x ``height`` px about to be decoded against the job's
        pixel budget; :class:`PixelBudgetExceeded` (413) if it would pass it, or if
        ``analysed`` (features will be extracted from it, or a board searched in it) and it
        has more than the pool's ``max_analysed_pixels``."""
        n = int(width) * int(height)
        if n < 0:
            raise ValueError(f"{name!r}: negative size {width} x {height}")
        if analysed and n > self._pool.max_analysed_pixels:
            raise PixelBudgetExceeded(
                f"{name!r} is {width} x {height} = {n} px; features are extracted and "
                f"boards searched in images of at most {self._pool.max_analysed_pixels} px "
                "(SIFT takes about 230 bytes per pixel): send a smaller image"
            )
        limit = self._pool.max_pixels
        if self.pixels + n > limit:
            raise PixelBudgetExceeded(
                f"{name!r} ({width} x {height} px) would bring this request to "
                f"{self.pixels + n} decoded pixels; one request may decode at most {limit} "
                "pixels in all: send fewer or smaller images per request"
            )
        self.pixels += n

    async def run(self, fn: Callable[..., T], /, *args: Any, **kwargs: Any) -> T:
        """``fn(*args, **kwargs)`` in a pool thread; :class:`ClientGone` if the client
        leaves before it has run (the queued call is dropped) or while it runs (its result
        is dropped)."""
        self.check()
        cf = self._pool._submit(fn, *args, **kwargs)
        self._holders += 1
        cf.add_done_callback(self._unit_done)
        fut = asyncio.wrap_future(cf, loop=self._loop)
        if self._cancel is None:
            try:
                return await fut
            except asyncio.CancelledError:
                cf.cancel()
                raise
        gone = asyncio.ensure_future(self._cancel.wait())
        either: set[asyncio.Future[Any]] = {fut, gone}
        try:
            await asyncio.wait(either, return_when=asyncio.FIRST_COMPLETED)
        except asyncio.CancelledError:
            cf.cancel()
            fut.add_done_callback(_mark_retrieved)
            raise
        finally:
            gone.cancel()
        if fut.done():
            return fut.result()
        cf.cancel()  # dropped if still queued; a running unit ends on its own
        fut.add_done_callback(_mark_retrieved)
        raise ClientGone("the client disconnected; its queued work was dropped")

    def _unit_done(self, _cf: concurrent.futures.Future[Any]) -> None:
        # In the worker thread (or at once, for a cancelled unit): hand over to the loop.
        with contextlib.suppress(RuntimeError):  # a closed loop has nothing left to release
            self._loop.call_soon_threadsafe(self._release_one)

    def _release_one(self) -> None:
        self._holders -= 1
        if self._holders == 0:
            self._pool._held -= 1
            self._pool._slots.release()


class HeavyPool:
    """The worker threads and job slots of the heavy work (module docstring).

    Parameters
    ----------
    workers : int
        Threads, 1-64.
    max_jobs : int
        Requests doing heavy work at once, 1-256.
    admit_wait_s : float
        Longest wait for a job slot, seconds, in [0, 600] (0: refuse at once when full).
    max_pixels : int
        Decoded pixels one job may take in all, in [1, 10**9].
    max_analysed_pixels : int
        Pixels of the largest image analysed (features, board search), in [1, 10**9].
    """

    def __init__(
        self,
        *,
        workers: int = DEFAULT_WORKERS,
        max_jobs: int = DEFAULT_MAX_JOBS,
        admit_wait_s: float = DEFAULT_ADMIT_WAIT_S,
        max_pixels: int = DEFAULT_MAX_PIXELS,
        max_analysed_pixels: int = DEFAULT_MAX_ANALYSED_PIXELS,
    ) -> None:
        for name, value, lo, hi in (
            ("workers", workers, 1, 64),
            ("max_jobs", max_jobs, 1, 256),
            ("max_pixels", max_pixels, 1, 10**9),
            ("max_analysed_pixels", max_analysed_pixels, 1, 10**9),
        ):
            if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
                raise ValueError(f"{name} must be an integer in [{lo}, {hi}], got {value!r}")
        if (
            isinstance(admit_wait_s, bool)
            or not isinstance(admit_wait_s, int | float)
            or not 0 <= admit_wait_s <= 600
        ):
            raise ValueError(f"admit_wait_s must be in [0, 600] seconds, got {admit_wait_s!r}")
        self.workers = workers
        self.max_jobs = max_jobs
        self.admit_wait_s = float(admit_wait_s)
        self.max_pixels = max_pixels
        self.max_analysed_pixels = max_analysed_pixels
        self._executor = concurrent.futures.ThreadPoolExecutor(
            max_workers=workers, thread_name_prefix="visioncell-heavy"
        )
        self._slots = asyncio.Semaphore(max_jobs)
        self._held = 0  # slots held by admitted jobs (and their units still running)
        #: Jobs admitted, and requests refused as busy, since start.
        self.admitted = 0
        self.refused = 0

    @property
    def free_slots(self) -> int:
        """Job slots free now."""
        return self.max_jobs - self._held

    def _submit(
        self, fn: Callable[..., T], *args: Any, **kwargs: Any
    ) -> concurrent.futures.Future[T]:
        return self._executor.submit(fn, *args, **kwargs)

    @contextlib.asynccontextmanager
    async def job(
        self, *, cancel: asyncio.Event | None = None, wait_s: float | None = -1.0
    ) -> AsyncIterator[HeavyJob]:
        """A job slot for the block (module docstring).

        ``cancel`` is the request's "client gone" event; ``wait_s`` the longest wait for a
        slot (default ``admit_wait_s``; None: as long as it takes, for background jobs
        that are cancelled by their own means).  :class:`Busy` when no slot came in time,
        :class:`ClientGone` when the client left while waiting.
        """
        limit = self.admit_wait_s if wait_s is not None and wait_s < 0 else wait_s
        acquire = asyncio.ensure_future(self._slots.acquire())
        waits: set[asyncio.Future[Any]] = {acquire}
        gone = None if cancel is None else asyncio.ensure_future(cancel.wait())
        if gone is not None:
            waits.add(gone)
        try:
            if not acquire.done():
                await asyncio.wait(waits, timeout=limit, return_when=asyncio.FIRST_COMPLETED)
        except BaseException:
            await self._abandon(acquire)
            raise
        finally:
            if gone is not None:
                gone.cancel()
        if not acquire.done() or (cancel is not None and cancel.is_set()):
            await self._abandon(acquire)
            if cancel is not None and cancel.is_set():
                raise ClientGone("the client disconnected while its work waited for a slot")
            self.refused += 1
            raise Busy(
                f"the server is busy with {self.max_jobs} image or report jobs; none ended "
                f"within {limit:g} s: try again shortly",
                retry_after_s=max(1, round(limit or 1)),
            )
        self.admitted += 1
        self._held += 1
        job = HeavyJob(self, cancel)
        try:
            yield job
        finally:
            job._release_one()

    async def _abandon(self, acquire: asyncio.Future[Any]) -> None:
        """Give up a slot request: cancel it, or release the slot if it came meanwhile."""
        if not acquire.done():
            acquire.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await acquire
        if acquire.done() and not acquire.cancelled() and acquire.exception() is None:
            self._slots.release()

    def close(self) -> None:
        """Drop the queued work and let the threads end (running units finish)."""
        self._executor.shutdown(wait=False, cancel_futures=True)
