"""The automatic threshold follows every change of the trained views.

:class:`ThresholdKeeper` listens to the live index (a view taught, uploaded, imported by the
CLI and synced, deleted; a model renamed or deleted) and to the negative images, and
recomputes the automatic threshold (:func:`backend.recognition.thresholds.recompute`) as a
``threshold`` job of the cell:

* coalesced: it waits until nothing has changed for ``quiet_s`` (at most
  :data:`MAX_DELAY_FACTOR` times that after the first change), so a hundred uploads in a row
  give one recomputation; a change made while a recomputation runs supersedes it (it stops
  at its next held-out query, stores nothing) and one more follows after the quiet period;
* bounded: one recomputation at a time, over at most the index's views and
  :data:`~backend.recognition.negatives.MAX_NEGATIVES` stored negatives plus the cell's
  teach backgrounds;
* skipped when the newest automatic choice was made from the same data (its stored
  ``signature``: the views, their models and the negatives), e.g. after a rename back or
  when another cell of the plant already chose from the same views;
* held while a teach runs (:meth:`ThresholdKeeper.holding`): the teach stores its views and
  then either chooses at once through the keeper (:meth:`ThresholdKeeper.choose`, the same
  choice with the same negatives, so the keeper's own round after it is a skip) or leaves
  the choice to the last of its rounds; a choice running when a teach begins stops (its
  views are about to change) and runs again once the teach is over.  One choice runs at a
  time, the keeper's or a teach's.

The empty-belt backgrounds grabbed by this cell's teaches are negatives too.
"""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
import logging
from collections.abc import AsyncIterator, Callable, Sequence
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from backend.db.session import Database
from backend.jobs import Job, JobManager
from backend.recognition import negatives as neg
from backend.recognition import thresholds
from backend.recognition.index import LiveIndex
from backend.taskutil import cancel_and_wait

__all__ = ["MAX_DELAY_FACTOR", "Superseded", "ThresholdKeeper", "signature"]

log = logging.getLogger(__name__)

#: Longest wait after the first of a run of changes, in units of ``quiet_s``.
MAX_DELAY_FACTOR = 10.0

Backgrounds = Callable[[], Sequence[NDArray[np.uint8]]]


class Superseded(Exception):
    """A recomputation stopped because the views changed while it ran."""


def signature(live: LiveIndex, negative_ids: Sequence[int], n_backgrounds: int) -> str:
    """A digest of what a threshold is chosen from: every indexed view with its model and
    viewpoint, the stored negatives and the number of teach backgrounds."""
    with live.reading() as index:
        views = sorted((v.view_id, v.model, v.viewpoint) for v in index.views)
    h = hashlib.sha256()
    h.update(repr((views, list(negative_ids), n_backgrounds)).encode())
    return h.hexdigest()[:32]


class ThresholdKeeper:
    """Recomputes the automatic threshold after changes (module docstring).

    Parameters
    ----------
    db, live : the cell's database and live index.
    jobs : JobManager
        Where the ``threshold`` jobs run (the console lists them with the others).
    quiet_s : float
        Quiet period before a recomputation, seconds (``Settings.threshold_quiet_s``).
    backgrounds : callable, optional
        The cell's teach backgrounds (empty-belt images), negatives too.
    """

    def __init__(
        self,
        db: Database,
        live: LiveIndex,
        jobs: JobManager,
        *,
        quiet_s: float = 2.0,
        backgrounds: Backgrounds | None = None,
        target_far: float = thresholds.DEFAULT_TARGET_FAR,
    ) -> None:
        if not (0.0 <= quiet_s <= 600.0):
            raise ValueError(f"quiet_s must be within [0, 600] s, got {quiet_s!r}")
        self.db = db
        self.live = live
        self.jobs = jobs
        self.quiet_s = float(quiet_s)
        self.target_far = target_far
        self._backgrounds = backgrounds or (lambda: ())
        self._event = asyncio.Event()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._task: asyncio.Task[None] | None = None
        self._pending = False
        self._superseded = False
        self._job: Job | None = None
        self._choosing = False
        self._lock = asyncio.Lock()
        self._holds = 0
        self._free = asyncio.Event()
        self._free.set()
        #: Recomputations finished (skipped ones included), for the console and the tests.
        self.runs = 0
        #: Recomputations stopped by a change while they ran.
        self.superseded = 0
        #: The last recomputation's outcome (``ThresholdOutcome.public()`` plus ``skipped``).
        self.last: dict[str, Any] | None = None

    # -- life cycle -------------------------------------------------------------------
    def start(self) -> None:
        """Start listening (on the running event loop)."""
        if self._task is not None:
            return
        self._loop = asyncio.get_running_loop()
        self.live.add_listener(self._from_any_thread)
        self._task = self._loop.create_task(self._run(), name="threshold-keeper")

    async def stop(self) -> None:
        """Stop listening; a recomputation running is cancelled."""
        self.live.remove_listener(self._from_any_thread)
        task, self._task = self._task, None
        if task is not None:
            await cancel_and_wait(task)
        job = self._job
        if job is not None and job.task is not None and not job.task.done():
            await cancel_and_wait(job.task)

    # -- news of changes ---------------------------------------------------------------
    def _from_any_thread(self) -> None:
        loop = self._loop
        if loop is None or loop.is_closed():
            return
        with contextlib.suppress(RuntimeError):  # the loop closed meanwhile
            loop.call_soon_threadsafe(self.changed)

    def changed(self) -> None:
        """Note a change (on the event loop): a recomputation follows after the quiet period."""
        self._pending = True
        if self._running():
            self._superseded = True  # read by the running choice's progress callback
        self._event.set()

    def _running(self) -> bool:
        job = self._job
        return self._choosing or (job is not None and job.task is not None and not job.task.done())

    @contextlib.asynccontextmanager
    async def holding(self) -> AsyncIterator[None]:
        """Hold the keeper's own recomputations for the block (a teach: its views are about
        to change).  A recomputation running stops at its next held-out query and runs
        again after the block; :meth:`choose` still runs inside it."""
        self._holds += 1
        self._free.clear()
        if self._job is not None and self._job.task is not None and not self._job.task.done():
            self._superseded = True
        try:
            yield
        finally:
            self._holds -= 1
            if self._holds == 0:
                self._free.set()

    def status(self) -> dict[str, Any]:
        """``state`` (``idle``, ``waiting``: changes seen, quiet period running; ``running``),
        the running job's id, the number of runs and the last outcome."""
        job = self._job
        running = self._running()
        state = "running" if running else "waiting" if self._pending else "idle"
        return {
            "state": state,
            "job": None if job is None else job.id,
            "runs": self.runs,
            "superseded": self.superseded,
            "quiet_s": self.quiet_s,
            "last": self.last,
        }

    async def settled(self) -> None:
        """Return once no change is waiting and no recomputation runs (bound it with a
        timeout of your own)."""
        while True:
            job = self._job
            if job is not None and job.task is not None and not job.task.done():
                await asyncio.wait({job.task})
                continue
            if not self._pending:
                return
            await asyncio.sleep(0.01)

    # -- the loop -----------------------------------------------------------------------
    async def _quiet(self) -> None:
        """Wait until no change came for ``quiet_s`` (at most the longest delay)."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + MAX_DELAY_FACTOR * self.quiet_s
        while True:
            self._event.clear()
            left = min(self.quiet_s, deadline - loop.time())
            if left <= 0:
                return
            try:
                await asyncio.wait_for(self._event.wait(), left)
            except TimeoutError:
                return

    async def _run(self) -> None:
        while True:
            await self._event.wait()
            try:
                await self._quiet()
                await self._free.wait()  # no teach running
                self._pending = False
                self._superseded = False
                if len(self.live) == 0:  # nothing trained (a fresh cell): nothing to choose
                    continue
                job = self.jobs.start("threshold", self._body, params={"trigger": "change"})
                self._job = job
                assert job.task is not None
                await asyncio.wait({job.task})
            except asyncio.CancelledError:
                raise
            except Exception:  # keep listening whatever one round did
                log.exception("automatic threshold round failed")

    async def choose(self, report: Callable[[float, str], None]) -> thresholds.ThresholdOutcome:
        """Choose the threshold now, as a round of the keeper would (the same negatives and
        signature), for a teach that has just stored its views; ``report(fraction,
        message)`` follows its progress.  A change made meanwhile stops it: the outcome
        then says so and the keeper chooses again after the change."""
        async with self._lock:
            # The teach's own changes (its views, its model's measured height) are notified
            # through the event loop: let them arrive before this choice starts, so that only
            # a change made while it runs stops it.
            await asyncio.sleep(0)
            self._choosing = True
            self._superseded = False
            try:
                return await self._choose(report)
            except Superseded:
                self.superseded += 1
                outcome = await thresholds.deferred(self.db)
                return replace(outcome, reason="not chosen: the views changed meanwhile; "
                               "the automatic threshold follows them")  # fmt: skip
            finally:
                self._choosing = False

    async def _body(self, job: Job) -> dict[str, Any]:
        async with self._lock:
            try:
                outcome = await self._choose(job.report)
            except Superseded:
                self.superseded += 1
                self._pending = True  # a teach began or the views changed: once more after it
                self._event.set()
                return {"superseded": True, "reason": "the views changed meanwhile: chosen again"}
        self.runs += 1
        self.last = outcome.public() | {"skipped": outcome.skipped}
        return self.last

    async def _choose(self, report: Callable[[float, str], None]) -> thresholds.ThresholdOutcome:
        report(0.0, "reading the negatives")
        ids = await neg.negative_ids(self.db)
        backgrounds = list(self._backgrounds())
        sig = signature(self.live, ids, len(backgrounds))
        async with self.db.session() as session:
            row = await thresholds.latest_settings(session)
        if row is not None and row.chosen_by == "auto" and row.detail.get("signature") == sig:
            return thresholds.from_settings(row, "chosen from the same views and negatives already")
        images = await neg.load_negatives(self.db) + backgrounds
        loop = asyncio.get_running_loop()

        def progress(done: int, total: int) -> None:  # called from the worker thread
            if self._superseded:
                raise Superseded
            loop.call_soon_threadsafe(
                report, 0.05 + 0.9 * done / max(total, 1), f"held-out query {done}/{total}"
            )

        outcome = await thresholds.recompute(
            self.db, self.live, target_far=self.target_far, negatives=images,
            signature=sig, progress=progress,
        )  # fmt: skip
        return replace(outcome, negatives=len(images))
