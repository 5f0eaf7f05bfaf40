"""What lets a cell survive faults: in-progress markers, database outages,
station backgrounds that outlive the process.

* :func:`begin` commits an :class:`~backend.db.models.InspectionInProgress` marker before an
  inspection moves the arm; :func:`backend.inspection.results.store` deletes it in the
  transaction that writes the result.  A marker found by :func:`mark_interrupted` at
  start-up is an inspection the process did not finish (SIGKILL, power loss): it becomes a
  complete ``failed`` row with the reason ``interrupted`` and the marker goes, in one
  transaction, so it is reported once and never twice.
* :func:`is_database_error` tells an unavailable database (connection refused, server
  gone, SQLite file locked) from a programming error; :func:`retry_database` waits it out
  with :class:`robot.backoff.Backoff` (exponential with jitter), never giving up on a
  result that must be stored, but giving up at once when the caller is cancelled.
* :func:`load_backgrounds` / :func:`save_background` keep the empty-belt backgrounds of the
  teaches in the database, so a restarted process inspects without teaching again.
"""

from __future__ import annotations

import asyncio
import logging
import os
import socket
from collections.abc import Awaitable, Callable
from typing import Any, TypeVar

import numpy as np
from numpy.typing import NDArray
from sqlalchemy import delete, select
from sqlalchemy.exc import DBAPIError, InterfaceError, OperationalError
from sqlalchemy.exc import TimeoutError as PoolTimeout

from backend.db.models import Decision, Inspection, InspectionInProgress, StationBackground, utcnow
from backend.db.session import Database, changed
from robot.backoff import Backoff

__all__ = ["alive_elsewhere", "begin", "is_database_error", "load_backgrounds", "mark_interrupted", "owner_tag",
           "retry_database", "save_background"]  # fmt: skip

log = logging.getLogger(__name__)

T = TypeVar("T")

#: Reason prefix of an inspection found unfinished at start-up.
INTERRUPTED = "interrupted"


def owner_tag() -> str:
    """``host:pid`` of this process (names the process that left a marker)."""
    return f"{socket.gethostname()[:100]}:{os.getpid()}"


def is_database_error(exc: BaseException) -> bool:
    """True when ``exc`` means the database cannot be reached or written now (it may come
    back): SQLAlchemy's operational / interface errors, a connection error under them, a
    pool timeout, or an ``OSError`` from the driver (PostgreSQL refused or reset)."""
    if isinstance(exc, OperationalError | InterfaceError | PoolTimeout):
        return True
    if isinstance(exc, DBAPIError) and exc.connection_invalidated:
        return True
    if isinstance(exc, ConnectionError | OSError | TimeoutError):
        return True
    name = type(exc).__module__ + "." + type(exc).__name__
    # asyncpg's own errors when the server goes away (not wrapped by SQLAlchemy on connect).
    return name.startswith("asyncpg.") and (
        "Connection" in name or "CannotConnectNow" in name or "AdminShutdown" in name
    )


async def retry_database(
    what: str,
    fn: Callable[[], Awaitable[T]],
    *,
    backoff: Backoff | None = None,
    max_wait_s: float | None = None,
    on_wait: Callable[[str], None] | None = None,
) -> T:
    """``await fn()``, again after a backoff wait while it fails with a database error.

    Parameters
    ----------
    what : str
        What is being done, for the log (once per outage) and ``on_wait``.
    max_wait_s : float, optional
        Give up (re-raise the last error) after this long; None: until cancelled.
    on_wait : callable, optional
        ``on_wait(message)`` at every failed attempt (e.g. a job's progress message).
    """
    b = backoff or Backoff(initial_s=0.2, max_s=5.0)
    loop = asyncio.get_running_loop()
    t0 = loop.time()
    logged = False
    while True:
        try:
            out = await fn()
        except Exception as exc:
            if not is_database_error(exc):
                raise
            if max_wait_s is not None and loop.time() - t0 >= max_wait_s:
                raise
            msg = f"database unavailable while {what}: {type(exc).__name__}: {str(exc)[:200]}"
            if not logged:
                log.warning("%s; retrying with backoff", msg)
                logged = True
            if on_wait is not None:
                on_wait(msg)
            await b.sleep()
            continue
        if logged:
            log.info("database back: %s done after %.1f s", what, loop.time() - t0)
        return out


async def begin(db: Database, cell_id: int, policy: str) -> int:
    """Commit the in-progress marker of an inspection about to start; returns its id."""
    async with db.session() as session:
        row = InspectionInProgress(
            cell_id=cell_id, started_at=utcnow(), policy=policy[:16], owner=owner_tag()
        )
        session.add(row)
        await session.flush()
        return int(row.id)


def alive_elsewhere(owner: str) -> bool:
    """Whether ``owner`` (``host:pid``) is another process of this host that still runs
    (a CLI run beside ``serve``): its inspection is not interrupted."""
    host, _, pid = owner.rpartition(":")
    if host != socket.gethostname()[:100] or not pid.isdigit() or int(pid) == os.getpid():
        return False
    try:
        os.kill(int(pid), 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


async def mark_interrupted(
    db: Database, cell_id: int, *, owners: dict[int, str] | None = None
) -> list[int]:
    """Turn every marker of ``cell_id`` left by an earlier process into a complete ``failed``
    row (reason ``interrupted: ...``) with its report record, removing the markers in the
    same transaction.
    Returns the new inspection ids (and fills ``owners``, if given, with the process that
    left each: new id -> ``host:pid``).  Run at start-up, before this process inspects."""
    from backend.reports.blocks import append as append_records

    async with db.session() as session:
        markers = (
            await session.scalars(
                select(InspectionInProgress)
                .where(InspectionInProgress.cell_id == cell_id)
                .order_by(InspectionInProgress.id)
            )
        ).all()
        markers = [m for m in markers if not alive_elsewhere(m.owner)]
        rows = []
        now = utcnow()
        for m in markers:
            reason = (
                f"{INTERRUPTED}: the process {m.owner or '?'} ended during the inspection "
                f"started at {m.started_at.isoformat()}; found at start-up"
            )
            row = Inspection(
                cell_id=cell_id, started_at=m.started_at, finished_at=now,
                decision=Decision.failed, policy=m.policy, reason=reason, note=reason,
                viewpoints_visited=[], durations={}, scores={},
            )  # fmt: skip
            session.add(row)
            rows.append(row)
        if markers:
            changed(session, "inspections")
            await session.execute(
                delete(InspectionInProgress).where(
                    InspectionInProgress.id.in_([m.id for m in markers])
                )
            )
        await session.flush()
        ids = [int(r.id) for r in rows]
        if owners is not None:
            owners.update({i: m.owner for i, m in zip(ids, markers, strict=True)})
        await append_records(session, [{
            "cell_id": cell_id, "started_at": r.started_at, "decision": r.decision,
            "model_name": None, "policy": r.policy, "duration_s": None, "score": None,
            "durations": {}, "viewpoints_visited": [], "truth": None,
        } for r in rows])  # fmt: skip
    if ids:
        log.warning("%d inspection(s) interrupted by the last shutdown marked failed: %s",
                    len(ids), ids)  # fmt: skip
    return ids


async def load_backgrounds(
    db: Database, cell_id: int
) -> dict[tuple[float, ...], NDArray[np.uint8]]:
    """The stored empty-belt backgrounds of the cell, by shot key (newest per key)."""
    from backend.recognition.images import rgb_from_png

    out: dict[tuple[float, ...], NDArray[np.uint8]] = {}
    async with db.session() as session:
        rows = (
            await session.scalars(
                select(StationBackground)
                .where(StationBackground.cell_id == cell_id)
                .order_by(StationBackground.id)
            )
        ).all()
        for r in rows:
            out[tuple(float(v) for v in r.shot_key)] = await asyncio.to_thread(
                rgb_from_png, r.image_png
            )
    return out


async def save_background(
    db: Database, cell_id: int, key: tuple[float, ...], image: NDArray[np.uint8]
) -> None:
    """Store (replace) the background of one shot of the cell."""
    from backend.recognition.images import encode_png

    png = await asyncio.to_thread(encode_png, image)
    k = [float(v) for v in key]

    async def write() -> None:
        async with db.session() as session:
            for r in (
                await session.scalars(
                    select(StationBackground).where(StationBackground.cell_id == cell_id)
                )
            ).all():
                if [round(float(v), 4) for v in r.shot_key] == k:
                    await session.delete(r)
            session.add(StationBackground(cell_id=cell_id, shot_key=k, image_png=png))

    await retry_database("storing a station background", write, max_wait_s=120.0)


def background_saver(db: Database, cell_id: int) -> Callable[[tuple[float, ...], Any], None]:
    """A :attr:`BackgroundStore.on_put` hook storing each new background (in a task)."""
    tasks: set[asyncio.Task[None]] = set()

    def on_put(key: tuple[float, ...], image: Any) -> None:
        t = asyncio.get_running_loop().create_task(save_background(db, cell_id, key, image.copy()))
        tasks.add(t)

        def done(task: asyncio.Task[None]) -> None:
            tasks.discard(task)
            if not task.cancelled() and task.exception() is not None:
                log.error("storing a station background failed: %s", task.exception())

        t.add_done_callback(done)

    return on_put
