"""Keep a process's live index in step with changes made by the plant's other processes.

Two ``visioncell serve`` processes with different cell names share one PostgreSQL database,
and so their object models and trained views: a model taught on one cell must be used by the
other without a restart.  :class:`IndexSync` runs one task per process that

1. on PostgreSQL, LISTENs on :data:`backend.db.changes.CHANNEL` over its own asyncpg
   connection; every committed change of a model or view notifies it
   (:mod:`backend.db.changes`), and it syncs at once;
2. otherwise (SQLite, ``index_listen`` off, or the listening connection lost and not yet
   back) polls :func:`fingerprint`, a cheap change counter, every ``index_poll_s``;
   while listening, the same check runs every :data:`LISTEN_CHECK_S` as a safety net and a
   keep-alive of the connection.

A sync compares the fingerprint with the last one; when it moved it reads the ids of every
model and view (no images, no features), asks :meth:`LiveIndex.diff` what differs, loads
the features of the new views only and applies the change with :meth:`LiveIndex.apply`
(retried when a local change slipped in between; a view this process indexed just before
its own commit is kept for :data:`~backend.recognition.index.LOCAL_GRACE_S` although the
snapshot lacks it).  A lost connection or a database that is
away is logged and retried: the cell never stops for it, and the first sync after it
catches up on everything missed (the snapshot is complete, not a replay of events).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from dataclasses import dataclass, field
from typing import Any

from sqlalchemy import func, select
from sqlalchemy.engine import make_url

from backend.db.changes import CHANNEL
from backend.db.models import AuditEntry, ObjectModel, TrainedView
from backend.db.session import Database
from backend.recognition.index import VIEW_ROW_COLUMNS, IndexedModel, LiveIndex, ViewRow
from backend.taskutil import cancel_and_wait

__all__ = ["LISTEN_CHECK_S", "IndexSync", "SyncReport", "fingerprint"]

log = logging.getLogger(__name__)

#: Fingerprint check while LISTEN works (safety net, keeps the connection checked), s.
LISTEN_CHECK_S = 30.0
#: Longest wait between two attempts to (re)open the listening connection, s.
MAX_RECONNECT_S = 30.0
#: Views whose features one query loads.
LOAD_CHUNK = 100
#: Attempts to apply a diff when local changes keep slipping in between.
APPLY_ATTEMPTS = 3
#: Timeout of one database step of a sync (connect, keep-alive), s.
STEP_TIMEOUT_S = 10.0

Fingerprint = tuple[int, ...]


async def fingerprint(db: Database) -> Fingerprint:
    """A change counter of the models and views, in one cheap query (indexes only).

    Every change of a model or view writes an audit row in its own transaction
    (:mod:`backend.audit`), so the newest audit id moves with each; the counts and newest
    ids of the two tables move with changes made without the audit trail (a bulk delete).
    """
    q = select(
        select(func.coalesce(func.max(AuditEntry.id), 0)).scalar_subquery(),
        select(func.count(ObjectModel.id)).scalar_subquery(),
        select(func.coalesce(func.max(ObjectModel.id), 0)).scalar_subquery(),
        select(func.count(TrainedView.id)).scalar_subquery(),
        select(func.coalesce(func.max(TrainedView.id), 0)).scalar_subquery(),
    )
    async with db.session() as session:
        row = (await session.execute(q)).one()
    return tuple(int(v) for v in row)


@dataclass
class SyncReport:
    """What one sync did."""

    changed: bool
    models_put: int = 0
    models_dropped: int = 0
    views_loaded: int = 0
    views_removed: int = 0
    seconds: float = 0.0


@dataclass
class SyncStats:
    """Counters for the status of the sync task."""

    mode: str = "starting"
    syncs: int = 0
    changes: int = 0
    notifications: int = 0
    errors: int = 0
    last_error: str = ""
    last_sync_at: float | None = None
    reconnects: int = 0
    extra: dict[str, Any] = field(default_factory=dict)


class IndexSync:
    """The task keeping ``live`` in step with the database (see the module doc).

    Parameters
    ----------
    db, live
        The process's database and live index.
    poll_s : float
        Fingerprint period without LISTEN (``Settings.index_poll_s``), 0.05..60 s.
    listen : bool
        Use PostgreSQL LISTEN/NOTIFY when the database is PostgreSQL.
    """

    def __init__(self, db: Database, live: LiveIndex, *, poll_s: float = 2.0, listen: bool = True):
        if not 0.05 <= float(poll_s) <= 60.0:
            raise ValueError(f"poll_s must be within 0.05..60 s, got {poll_s!r}")
        self.db = db
        self.live = live
        self.poll_s = float(poll_s)
        self._pg = db.url.startswith("postgresql")
        self.listen = bool(listen) and self._pg
        self._last: Fingerprint | None = None
        self._wake = asyncio.Event()
        self._conn: Any = None
        self._next_connect = 0.0
        self._backoff = 0.5
        self._task: asyncio.Task[None] | None = None
        self.stats = SyncStats()
        #: Set after each completed sync (tests and benchmarks wait on it).
        self.synced = asyncio.Event()

    # -- life cycle -----------------------------------------------------------------------
    def start(self) -> None:
        """Start the task (inside the running loop)."""
        if self._task is None:
            self._task = asyncio.get_running_loop().create_task(self._run(), name="index-sync")

    async def stop(self) -> None:
        """Stop the task and close the listening connection."""
        task, self._task = self._task, None
        if task is not None:
            await cancel_and_wait(task)  # not a bare cancel: wait_for may swallow one
        await self._close_conn()

    def poke(self) -> None:
        """Sync as soon as possible."""
        self._wake.set()

    @property
    def listening(self) -> bool:
        """Whether the LISTEN connection is open."""
        return self._conn is not None and not self._conn.is_closed()

    # -- one sync ---------------------------------------------------------------------------
    async def sync_once(self) -> SyncReport:
        """Bring the index up to date if the fingerprint moved since the last sync."""
        t0 = time.perf_counter()
        fp = await fingerprint(self.db)
        if fp == self._last:
            return SyncReport(False, seconds=time.perf_counter() - t0)
        for _ in range(APPLY_ATTEMPTS):
            diff = self.live.diff(*await self._snapshot())
            rows = await self._load(diff.load_views) if diff.load_views else []
            ids = tuple(r[0] for r in rows)
            images = await self._load_images(ids) if ids else {}
            # The index's lock may be held by a recognition thread: wait for it off the loop.
            if await asyncio.to_thread(self.live.apply, diff, rows, images):
                # A deferred diff kept views this process added that the snapshot lacked:
                # leave the fingerprint unseen, so a later round looks again.
                self._last = None if diff.deferred else fp
                report = SyncReport(
                    not diff.empty,
                    len(diff.put_models),
                    len(diff.drop_models),
                    len(rows),
                    len(diff.remove_views),
                    time.perf_counter() - t0,
                )
                if report.changed:
                    self.stats.changes += 1
                    log.info(
                        "index sync: %d models changed, %d gone, %d views loaded, %d removed",
                        report.models_put, report.models_dropped, report.views_loaded,
                        report.views_removed,
                    )  # fmt: skip
                return report
        # Local changes kept coming: leave the fingerprint unseen so the next round retries.
        return SyncReport(False, seconds=time.perf_counter() - t0)

    async def _snapshot(
        self,
    ) -> tuple[dict[int, IndexedModel], dict[int, tuple[int, str, str]]]:
        async with self.db.session() as session:
            models = {m.id: IndexedModel.of(m) for m in await session.scalars(select(ObjectModel))}
            rows = (
                await session.execute(
                    select(
                        TrainedView.id,
                        TrainedView.model_id,
                        TrainedView.descriptor_kind,
                        TrainedView.descriptor_version,
                    )
                )
            ).all()
        return models, {int(v): (int(m), str(k), str(ver)) for v, m, k, ver in rows}

    async def _load(self, ids: tuple[int, ...]) -> list[ViewRow]:
        out: list[ViewRow] = []
        for i in range(0, len(ids), LOAD_CHUNK):
            chunk = ids[i : i + LOAD_CHUNK]
            async with self.db.session() as session:
                rows = (
                    await session.execute(
                        select(*VIEW_ROW_COLUMNS).where(TrainedView.id.in_(chunk))
                    )
                ).all()
            out.extend(
                (int(a), int(b), int(c), bytes(d), str(e), str(f)) for a, b, c, d, e, f in rows
            )
        return out

    async def _load_images(self, ids: tuple[int, ...]) -> dict[int, tuple[bytes, bytes | None]]:
        """Stored image and mask of the views ``ids`` (side views' colour signatures, top
        views' belt colour)."""
        out: dict[int, tuple[bytes, bytes | None]] = {}
        for i in range(0, len(ids), LOAD_CHUNK):
            chunk = ids[i : i + LOAD_CHUNK]
            async with self.db.session() as session:
                rows = (
                    await session.execute(
                        select(TrainedView.id, TrainedView.image_png, TrainedView.mask_png).where(
                            TrainedView.id.in_(chunk)
                        )
                    )
                ).all()
            for vid, png, mask_png in rows:
                out[int(vid)] = (bytes(png), None if mask_png is None else bytes(mask_png))
        return out

    # -- the task ---------------------------------------------------------------------------
    async def _run(self) -> None:
        while True:
            listening = await self._ensure_listener()
            self.stats.mode = "listen" if listening else "poll"
            wait = LISTEN_CHECK_S if listening else self.poll_s
            if listening:
                wait = max(wait, self.poll_s)
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._wake.wait(), wait)
            self._wake.clear()
            try:
                if listening:
                    await self._keepalive()
                await asyncio.wait_for(self.sync_once(), STEP_TIMEOUT_S * 3)
                self.stats.syncs += 1
                self.stats.last_sync_at = time.time()
                self.synced.set()
            except asyncio.CancelledError:
                raise
            except Exception as exc:  # the database away, a lost connection: try again later
                self.stats.errors += 1
                self.stats.last_error = f"{type(exc).__name__}: {exc}"[:300]
                log.warning("index sync failed (will retry): %s", self.stats.last_error)

    async def _keepalive(self) -> None:
        try:
            await asyncio.wait_for(self._conn.execute("SELECT 1"), STEP_TIMEOUT_S)
        except Exception as exc:
            log.warning("index sync: the listening connection is lost (%s)", exc)
            await self._close_conn()

    async def _ensure_listener(self) -> bool:
        if not self.listen:
            return False
        if self.listening:
            return True
        if self._conn is not None:  # closed under us
            await self._close_conn()
        now = time.monotonic()
        if now < self._next_connect:
            return False
        try:
            conn = await asyncio.wait_for(self._connect(), STEP_TIMEOUT_S)
            await conn.add_listener(CHANNEL, self._on_notify)
            conn.add_termination_listener(self._on_lost)
        except Exception as exc:
            self._next_connect = now + self._backoff
            self._backoff = min(MAX_RECONNECT_S, self._backoff * 2)
            self.stats.last_error = f"listen: {type(exc).__name__}: {exc}"[:300]
            log.warning("index sync: cannot LISTEN (%s); polling meanwhile", exc)
            return False
        self._conn = conn
        self._backoff = 0.5
        self.stats.reconnects += 1
        self._wake.set()  # changes made while not listening: catch up at once
        return True

    async def _connect(self) -> Any:
        import asyncpg  # type: ignore[import-untyped]

        u = make_url(self.db.url)
        return await asyncpg.connect(
            host=u.host or "127.0.0.1",
            port=u.port or 5432,
            user=u.username,
            password=u.password,
            database=u.database,
        )

    def _on_notify(self, _conn: Any, _pid: int, _channel: str, _payload: str) -> None:
        self.stats.notifications += 1
        self._wake.set()

    def _on_lost(self, _conn: Any) -> None:
        self._wake.set()  # the loop notices the closed connection and polls / reconnects

    async def _close_conn(self) -> None:
        conn, self._conn = self._conn, None
        if conn is not None:
            with contextlib.suppress(Exception):
                await asyncio.wait_for(conn.close(), 2.0)
            if not conn.is_closed():
                conn.terminate()
