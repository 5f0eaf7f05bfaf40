"""Durable markers of running jobs, so that a job cut short by the process ending (kill -9,
power loss) is listed as ``interrupted`` by the next process.

Jobs live in memory (:class:`backend.jobs.JobManager`); :class:`JobJournal` listens to
their starts and ends and keeps one :class:`~backend.db.models.JobInProgress` row per
running job.  Writes never hold a job up: they go through one writer task, in order, a
batch per transaction, and a start whose end comes before it was written is never written
at all (a short move costs nothing).  While the database is away the writer waits it out
with backoff; on a clean shutdown it drains what is queued.

At start-up :func:`interrupted_jobs` turns the markers an earlier process left into ended
:class:`~backend.jobs.Job` records with the state ``interrupted`` (and deletes the
markers, so each is reported by one start-up only); the runtime adds them to the job
history, so ``/api/jobs`` and ``/api/jobs/{id}`` show them.  An inspection job also names
the inspection rows the same process left unfinished (stored as failed, reason
``interrupted``, by :func:`backend.inspection.recovery.mark_interrupted`).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
from collections import OrderedDict
from datetime import datetime
from typing import Any

from sqlalchemy import delete, insert, select

from backend.db.models import JobInProgress
from backend.db.session import Database
from backend.db.types import utcnow
from backend.inspection import recovery
from backend.jobs import Job, JobState
from robot.backoff import Backoff

__all__ = ["INSPECTION_KINDS", "MAX_PARAMS_BYTES", "MAX_PENDING", "JobJournal",
           "interrupted_jobs"]  # fmt: skip

log = logging.getLogger(__name__)

#: Largest parameters kept with a marker, bytes of JSON (larger: kept as ``{}``).
MAX_PARAMS_BYTES = 4096
#: Most marker writes waiting at once (beyond it new starts are not recorded, with a log).
MAX_PENDING = 10_000
#: Job kinds that inspect: their interrupted markers name the inspections left unfinished.
INSPECTION_KINDS = ("inspect", "inspection-run")
#: Longest wait at shutdown for the queued writes, seconds.
DRAIN_S = 5.0


def _params(params: dict[str, Any]) -> dict[str, Any]:
    try:
        text = json.dumps(params, allow_nan=False, default=str)
    except (TypeError, ValueError):
        return {}
    return params if len(text) <= MAX_PARAMS_BYTES else {}


class JobJournal:
    """Keeps the markers of a :class:`~backend.jobs.JobManager`'s running jobs (use it as
    the manager's listener: ``jobs.add_listener(journal)``)."""

    def __init__(self, db: Database, cell_id: int, *, owner: str | None = None) -> None:
        self.db = db
        self.cell_id = cell_id
        self.owner = recovery.owner_tag() if owner is None else owner
        #: Job id -> the row to insert (a start) or None (an end: delete the row).
        self._pending: OrderedDict[str, dict[str, Any] | None] = OrderedDict()
        self._wake = asyncio.Event()
        self._idle = asyncio.Event()
        self._idle.set()
        self._task: asyncio.Task[None] | None = None
        self._full_logged = False

    def start(self) -> None:
        """Start the writer task (on the running loop)."""
        if self._task is None:
            self._task = asyncio.get_running_loop().create_task(self._writer(), name="job-journal")

    async def close(self) -> None:
        """Write what is queued (at most :data:`DRAIN_S`), then stop the writer."""
        if self._task is None:
            return
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(DRAIN_S):
                await self._idle.wait()
        self._task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await self._task
        self._task = None

    def __call__(self, job: Job) -> None:
        """A job started or ended (the manager's listener; never blocks)."""
        if job.state is JobState.running:
            if len(self._pending) >= MAX_PENDING:
                if not self._full_logged:
                    log.warning("job journal: %d writes queued; job %s not recorded",
                                len(self._pending), job.id)  # fmt: skip
                    self._full_logged = True
                return
            self._pending[job.id] = {
                "id": job.id, "cell_id": self.cell_id, "kind": job.kind[:64],
                "started_at": job.created_at, "params": _params(job.params), "owner": self.owner,
            }  # fmt: skip
        elif job.id in self._pending and self._pending[job.id] is not None:
            del self._pending[job.id]  # ended before its start was written: nothing to undo
        else:
            self._pending[job.id] = None
        if self._pending:
            self._idle.clear()
            self._wake.set()

    async def _writer(self) -> None:
        backoff = Backoff(initial_s=0.2, max_s=5.0)
        logged = False
        while True:
            if not self._pending:
                self._full_logged = False
                self._idle.set()
                self._wake.clear()
                await self._wake.wait()
                continue
            batch = list(self._pending.items())
            self._pending.clear()
            try:
                await self._write(batch)
            except Exception as exc:
                if not recovery.is_database_error(exc):
                    log.exception("job journal: writing %d marker(s) failed; dropped", len(batch))
                    continue
                if not logged:
                    log.warning("job journal: database unavailable (%s); retrying",
                                type(exc).__name__)  # fmt: skip
                    logged = True
                self._requeue(batch)
                await backoff.sleep()
                continue
            if logged:
                log.info("job journal: database back")
                logged = False
            backoff.reset()

    def _requeue(self, batch: list[tuple[str, dict[str, Any] | None]]) -> None:
        """Put a failed batch back in front of what came meanwhile (newer ops win)."""
        newer = self._pending
        merged: OrderedDict[str, dict[str, Any] | None] = OrderedDict(batch)
        for job_id, op in newer.items():
            if op is None and merged.get(job_id) is not None:
                del merged[job_id]  # its start was never written
            else:
                merged[job_id] = op
        self._pending = merged

    async def _write(self, batch: list[tuple[str, dict[str, Any] | None]]) -> None:
        rows = [op for _, op in batch if op is not None]
        gone = [job_id for job_id, op in batch if op is None]
        async with self.db.session() as session:
            if gone:
                await session.execute(delete(JobInProgress).where(JobInProgress.id.in_(gone)))
            if rows:
                await session.execute(insert(JobInProgress), rows)


async def interrupted_jobs(
    db: Database, cell_id: int, *, inspections: dict[int, str] | None = None
) -> list[Job]:
    """The jobs an earlier process left running, as ended records with the state
    ``interrupted``; their markers are deleted (reported once).

    Parameters
    ----------
    inspections : dict, optional
        Inspection id -> owner (``host:pid``) of the inspections found unfinished at this
        start-up; an inspecting job names those of its own process (one motion job at a
        time per process: they were its).
    """
    now = utcnow()
    async with db.session() as session:
        markers = (
            await session.scalars(
                select(JobInProgress)
                .where(JobInProgress.cell_id == cell_id)
                .order_by(JobInProgress.started_at)
            )
        ).all()
        markers = [m for m in markers if not recovery.alive_elsewhere(m.owner)]
        if markers:
            await session.execute(
                delete(JobInProgress).where(JobInProgress.id.in_([m.id for m in markers]))
            )
        found = [(m.id, m.kind, m.started_at, dict(m.params or {}), m.owner) for m in markers]
    jobs = [_record(*f, now=now, inspections=inspections or {}) for f in found]
    if jobs:
        log.warning("%d job(s) interrupted by the last shutdown: %s",
                    len(jobs), ", ".join(f"{j.id} ({j.kind})" for j in jobs))  # fmt: skip
    return jobs


def _record(
    job_id: str,
    kind: str,
    started_at: datetime,
    params: dict[str, Any],
    owner: str,
    *,
    now: datetime,
    inspections: dict[int, str],
) -> Job:
    detail = (
        f"the process {owner or '?'} ended while this job ran (started at "
        f"{started_at.isoformat()}); found at start-up"
    )
    result = None
    if kind in INSPECTION_KINDS:
        ids = sorted(i for i, o in inspections.items() if o == owner)
        result = {"interrupted_inspections": ids}
        if ids:
            detail += f"; inspection(s) {', '.join(map(str, ids))} stored as failed (interrupted)"
    return Job(
        id=job_id, kind=kind, motion=False, state=JobState.interrupted, progress=0.0,
        message=f"interrupted: {detail}"[:500], created_at=started_at, finished_at=now,
        result=result, error={"error": "interrupted", "detail": detail}, params=params,
    )  # fmt: skip
