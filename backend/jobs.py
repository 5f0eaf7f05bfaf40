"""Long-running jobs (move, train, calibrate, inspect) with ids, progress and cancellation.

A job wraps a coroutine.  Jobs that move the arm hold the cell's one arm reservation: a
second motion job is refused at once with :class:`~robot.errors.RobotBusy` rather than
queued behind the first, so an operator never sees the arm start a move they have forgotten.
The reservation is taken synchronously in :meth:`JobManager.start` (two motion jobs started
in the same event-loop tick: the second is refused), and released when the job's task ends.

Inside a job's coroutine, :func:`current_job` names the job; the cell's motion building
blocks (``Cell.move_to`` and friends) use it to move under the reservation the job holds.

Every start, progress report and end is published on the cell's event bus
(:class:`~backend.cell.events.JobState`, :class:`~backend.cell.events.JobProgress`).
"""

from __future__ import annotations

import asyncio
import builtins
import contextlib
import contextvars
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

__all__ = ["ArmReservation", "Job", "JobManager", "JobState", "current_job"]

log = logging.getLogger(__name__)


class JobState(enum.StrEnum):
    """Life cycle of a job."""

    running = "running"
    done = "done"
    failed = "failed"
    cancelled = "cancelled"
    #: The process ended while the job ran (listed by the next process's start-up).
    interrupted = "interrupted"


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
    on_report: Callable[[Job], None] | None = field(default=None, repr=False, compare=False)

    def report(self, fraction: float, message: str = "") -> None:
        """Progress callback handed to the job's coroutine (published on the event bus)."""
        f = float(fraction)
        self.progress = min(max(f, 0.0), 1.0) if f == f else self.progress
        if message:
            self.message = message[:500]
        if self.on_report is not None:
            self.on_report(self)

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

_CURRENT_JOB: contextvars.ContextVar[Job | None] = contextvars.ContextVar(
    "visioncell_current_job", default=None
)


def current_job() -> Job | None:
    """The job whose coroutine is running (None outside any job)."""
    return _CURRENT_JOB.get()


class ArmReservation:
    """The one right to move the arm, taken synchronously and released once.

    Use it as a context manager (``with jobs.reserve_arm("what"):``) or call
    :meth:`release`.
    """

    def __init__(self, manager: JobManager, owner: str, job: Job | None) -> None:
        self._manager = manager
        self.owner = owner
        self.job = job
        self.released = False

    def release(self) -> None:
        """Give the arm back (idempotent)."""
        if not self.released:
            self.released = True
            if self._manager._arm is self:
                self._manager._arm = None

    def __enter__(self) -> ArmReservation:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


class JobManager:
    """Starts, tracks and cancels jobs; keeps the last ``history`` finished ones.

    Parameters
    ----------
    history : int
        Finished jobs remembered.
    publish : callable, optional
        ``publish(event)`` of the cell's event bus; job starts, ends and progress reports
        go there as :class:`~backend.cell.events.JobState` and
        :class:`~backend.cell.events.JobProgress`.
    """

    def __init__(self, *, history: int = 200, publish: Callable[[Any], None] | None = None) -> None:
        self._jobs: OrderedDict[str, Job] = OrderedDict()
        self._history = history
        self._arm: ArmReservation | None = None
        self._publish = publish
        self._listeners: list[Callable[[Job], None]] = []

    def add_listener(self, fn: Callable[[Job], None]) -> None:
        """Call ``fn(job)`` whenever a job starts or ends."""
        self._listeners.append(fn)

    def remove_listener(self, fn: Callable[[Job], None]) -> None:
        """Stop calling ``fn``."""
        if fn in self._listeners:
            self._listeners.remove(fn)

    def _notify(self, job: Job) -> None:
        if self._publish is not None:
            from backend.cell.events import JobState as JobStateEvent

            self._emit(JobStateEvent.of(job))
        for fn in list(self._listeners):
            try:
                fn(job)
            except Exception:  # a broken listener must not break the job
                log.exception("job listener failed")

    def _progress(self, job: Job) -> None:
        if self._publish is not None and job.state is JobState.running:
            from backend.cell.events import JobProgress

            self._emit(JobProgress.of(job))

    def _emit(self, event: Any) -> None:
        assert self._publish is not None
        try:
            self._publish(event)
        except Exception:  # a broken subscriber must not break the job
            log.exception("publishing %s failed", type(event).__name__)

    @property
    def arm_holder(self) -> ArmReservation | None:
        """Who holds the arm now (None when it is free)."""
        return self._arm

    def check_arm_free(self) -> None:
        """Raise :class:`RobotBusy` naming the holder of the arm, if there is one."""
        if self._arm is not None:
            raise RobotBusy(
                f"the arm is busy with {self._arm.owner}; stop it or wait for it to finish"
            )

    def reserve_arm(self, owner: str, *, job: Job | None = None) -> ArmReservation:
        """Take the arm now or raise :class:`RobotBusy` (never waits: there is no queue)."""
        self.check_arm_free()
        self._arm = ArmReservation(self, owner, job)
        return self._arm

    def holds_arm(self, job: Job | None) -> bool:
        """Whether ``job`` is the motion job holding the arm."""
        return job is not None and self._arm is not None and self._arm.job is job

    def start(
        self,
        kind: str,
        body: JobBody,
        *,
        motion: bool = False,
        params: dict[str, Any] | None = None,
    ) -> Job:
        """Run ``body(job)`` as a task; raise :class:`RobotBusy` if ``motion`` and the arm is
        taken.  The arm is reserved here, synchronously, before the task exists."""
        job = Job(id=uuid.uuid4().hex[:12], kind=kind, motion=motion, params=params or {})
        job.on_report = self._progress
        reservation = self.reserve_arm(f"job {job.id} ({kind})", job=job) if motion else None
        try:
            job.task = asyncio.create_task(
                self._run(job, body, reservation), name=f"job-{kind}-{job.id}"
            )
        except BaseException:
            if reservation is not None:
                reservation.release()
            raise
        job.task.add_done_callback(lambda _t: self._finished(job, reservation))
        self._jobs[job.id] = job
        self._trim()
        self._notify(job)
        return job

    async def _run(self, job: Job, body: JobBody, reservation: ArmReservation | None) -> None:
        _CURRENT_JOB.set(job)  # this task's own context
        try:
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
            if reservation is not None:
                reservation.release()
            job.finished_at = utcnow()
            self._notify(job)

    def _finished(self, job: Job, reservation: ArmReservation | None) -> None:
        """Task done callback: also covers a task cancelled before its first step, whose
        coroutine never ran (so its ``finally`` never did)."""
        if reservation is not None:
            reservation.release()
        if job.state is JobState.running:
            job.state = JobState.cancelled
            job.message = job.message or "cancelled before it started"
            job.finished_at = utcnow()
            self._notify(job)

    def _trim(self) -> None:
        while len(self._jobs) > self._history:
            oldest_id, oldest = next(iter(self._jobs.items()))
            if oldest.state is JobState.running:
                break
            del self._jobs[oldest_id]

    def remember(self, jobs: builtins.list[Job]) -> None:
        """Add jobs that ended elsewhere (an earlier process's, found interrupted at
        start-up) to the history, oldest first: they are listed and read like any other,
        never run."""
        for job in sorted(jobs, key=lambda j: j.created_at):
            if job.state is JobState.running or job.task is not None:
                raise ValueError(f"job {job.id} is not an ended record: {job.state.value}")
            self._jobs[job.id] = job
        self._trim()

    def get(self, job_id: str) -> Job | None:
        """The job with this id, if still remembered."""
        return self._jobs.get(job_id)

    def list(self) -> builtins.list[Job]:
        """Jobs, newest first."""
        return list(reversed(self._jobs.values()))

    def running(self, *, motion: bool | None = None) -> builtins.list[Job]:
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
