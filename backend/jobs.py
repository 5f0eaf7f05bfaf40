"""Long-running jobs (move, train, calibrate, inspect) with ids, progress and cancellation.

A job wraps a coroutine.  Jobs that move the arm take the cell's motion lock: a second
motion job is refused at once with :class:`~robot.errors.RobotBusy` rather than queued
behind the first, so an operator never sees the arm start a move they have forgotten.
"""

from __future__ import annotations

import asyncio
import contextlib
import enum
import logging
import uuid
from collections import OrderedDict
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from datetime import datetime
from typing import Any

from backend.db.types import utcnow
from robot.errors import RobotBusy
from vision.errors import VisionCellError

__all__ = ["Job", "JobManager", "JobState"]

log = logging.getLogger(__name__)


class JobState(enum.StrEnum):
    """Life cycle of a job."""

    running = "running"
    done = "done"
    failed = "failed"
    cancelled = "cancelled"


@dataclass
class Job:
    """A job's public state; ``progress`` is in [0, 1]."""

    id: str
    kind: str
    motion: bool
    state: JobState = JobState.running
    progress: float = 0.0
    message: str = ""
    created_at: datetime = field(default_factory=utcnow)
    finished_at: datetime | None = None
    result: dict[str, Any] | None = None
    error: dict[str, str] | None = None
    task: asyncio.Task[Any] | None = field(default=None, repr=False)
    params: dict[str, Any] = field(default_factory=dict)

    def report(self, fraction: float, message: str = "") -> None:
        """Progress callback handed to the job's coroutine."""
        self.progress = min(max(float(fraction), 0.0), 1.0)
        if message:
            self.message = message

    def public(self) -> dict[str, Any]:
        """JSON form for the API and the console."""
        return {
            "id": self.id,
            "kind": self.kind,
            "state": self.state.value,
            "progress": self.progress,
            "message": self.message,
            "params": self.params,
            "created_at": self.created_at.isoformat(),
            "finished_at": self.finished_at.isoformat() if self.finished_at else None,
            "result": self.result,
            "error": self.error,
        }


JobBody = Callable[[Job], Awaitable[dict[str, Any] | None]]


class JobManager:
    """Starts, tracks and cancels jobs; keeps the last ``history`` finished ones."""

    def __init__(self, *, history: int = 200) -> None:
        self._jobs: OrderedDict[str, Job] = OrderedDict()
        self._history = history
        self.motion_lock = asyncio.Lock()
        self._listeners: list[Callable[[Job], None]] = []

    def add_listener(self, fn: Callable[[Job], None]) -> None:
        """Call ``fn(job)`` whenever a job starts or ends."""
        self._listeners.append(fn)

    def remove_listener(self, fn: Callable[[Job], None]) -> None:
        """Stop calling ``fn``."""
        if fn in self._listeners:
            self._listeners.remove(fn)

    def _notify(self, job: Job) -> None:
        for fn in self._listeners:
            try:
                fn(job)
            except Exception:  # a broken listener must not break the job
                log.exception("job listener failed")

    def check_arm_free(self) -> None:
        """Raise :class:`RobotBusy` naming the job that holds the motion lock, if one does."""
        if self.motion_lock.locked():
            holder = next(
                (j for j in self._jobs.values() if j.motion and j.state is JobState.running), None
            )
            what = f"job {holder.id} ({holder.kind})" if holder else "another job"
            raise RobotBusy(f"the arm is busy with {what}; stop it or wait for it to finish")

    def start(
        self,
        kind: str,
        body: JobBody,
        *,
        motion: bool = False,
        params: dict[str, Any] | None = None,
    ) -> Job:
        """Run ``body(job)`` as a task; raise :class:`RobotBusy` if ``motion`` and the arm is taken."""
        if motion:
            self.check_arm_free()
        job = Job(id=uuid.uuid4().hex[:12], kind=kind, motion=motion, params=params or {})
        job.task = asyncio.create_task(self._run(job, body), name=f"job-{kind}-{job.id}")
        self._jobs[job.id] = job
        self._trim()
        self._notify(job)
        return job

    async def _run(self, job: Job, body: JobBody) -> None:
        lock = self.motion_lock if job.motion else contextlib.nullcontext()
        try:
            async with lock:  # type: ignore[attr-defined]
                job.result = await body(job)
            job.state = JobState.done
            job.progress = 1.0
        except asyncio.CancelledError:
            job.state = JobState.cancelled
            job.message = job.message or "cancelled"
        except VisionCellError as exc:
            job.state = JobState.failed
            job.error = {"error": exc.code, "detail": exc.detail}
        except Exception as exc:  # keep the cell alive; the error goes to the job record
            log.exception("job %s (%s) crashed", job.id, job.kind)
            job.state = JobState.failed
            job.error = {"error": "internal_error", "detail": f"{type(exc).__name__}: {exc}"}
        finally:
            job.finished_at = utcnow()
            self._notify(job)

    def _trim(self) -> None:
        while len(self._jobs) > self._history:
            oldest_id, oldest = next(iter(self._jobs.items()))
            if oldest.state is JobState.running:
                break
            del self._jobs[oldest_id]

    def get(self, job_id: str) -> Job | None:
        """The job with this id, if still remembered."""
        return self._jobs.get(job_id)

    def list(self) -> list[Job]:
        """Jobs, newest first."""
        return list(reversed(self._jobs.values()))

    def running(self, *, motion: bool | None = None) -> list[Job]:
        """Running jobs (only motion or non-motion ones if ``motion`` is given)."""
        return [
            j
            for j in self._jobs.values()
            if j.state is JobState.running and (motion is None or j.motion == motion)
        ]

    async def cancel(self, job: Job) -> None:
        """Cancel a running job and wait for it to end."""
        if job.task is not None and not job.task.done():
            job.task.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await job.task

    async def wait(self, job: Job) -> Job:
        """Wait for ``job`` to end (never raises for the job's own errors)."""
        if job.task is not None:
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await asyncio.shield(job.task)
        return job

    async def shutdown(self) -> None:
        """Cancel every running job."""
        for job in self.running():
            await self.cancel(job)
