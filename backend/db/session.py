"""Async engine and session factory."""

from __future__ import annotations

import asyncio
import logging
from collections.abc import AsyncIterator, Callable, Iterable, Mapping
from contextlib import asynccontextmanager
from typing import Any

from sqlalchemy import event
from sqlalchemy.engine import make_url
from sqlalchemy.ext.asyncio import (
    AsyncEngine,
    AsyncSession,
    async_sessionmaker,
    create_async_engine,
)

__all__ = [
    "API_SLOTS",
    "POOL_OVERFLOW",
    "POOL_SIZE",
    "POOL_TIMEOUT_S",
    "Changes",
    "Database",
    "DatabaseBusy",
    "changed",
]

log = logging.getLogger(__name__)

#: Pooled connections kept open, and how many more may be opened at busy times.
POOL_SIZE = 5
POOL_OVERFLOW = 10
#: Connections REST requests may hold at once (``backend.api.deps``); the rest of the pool
#: stays for the cell itself (inspections, teaching, jobs): under a surge of readers on a
#: starved machine the readers took all 15 and the inspection in progress waited for one
#: (``benchmarks/load.py``, ``tests/backend/test_bug_readers_starve_the_cell_of_connections.py``).
API_SLOTS = 10
#: How long a session waits for a pooled connection (and a REST request for one of its
#: :data:`API_SLOTS`) before giving up: the API then answers 503 with ``Retry-After``
#: (``backend.api.errors``) instead of holding the client for SQLAlchemy's default 30 s.
POOL_TIMEOUT_S = 10.0


#: What a transaction changed, by topic (a table name, or ``"users"`` for sign-ins): the
#: ids it touched, or None for "any row".
Changes = Mapping[str, frozenset[int] | None]
_CHANGES = "visioncell_changes"


def changed(session: Any, topic: str, ids: Iterable[int] | None = None) -> None:
    """Note that ``session``'s transaction writes ``topic`` (the rows ``ids``; None: any
    row).  The services that write call it; when the session of :meth:`Database.session`
    ends, the database's :attr:`~Database.on_change` hooks get every change noted (the
    runtime's caches drop what they read of it)."""
    if not isinstance(topic, str) or not topic:
        raise ValueError(f"topic must be a non-empty string, got {topic!r}")
    noted: dict[str, set[int] | None] = session.info.setdefault(_CHANGES, {})
    if ids is None or (topic in noted and noted[topic] is None):
        noted[topic] = None
    else:
        noted[topic] = set(noted.get(topic) or ()) | {int(i) for i in ids}


class DatabaseBusy(Exception):
    """Every connection a REST request may hold is busy for longer than the pool's wait."""


class Database:
    """The engine and session factory of one process.

    SQLite gets foreign keys switched on (they are off by default) and a busy timeout so
    the API and the cell tasks can share the file.
    """

    def __init__(
        self,
        url: str,
        *,
        echo: bool = False,
        busy_timeout_s: float = 30.0,
        pool_timeout_s: float | None = None,
    ) -> None:
        self.url = url
        wait_s = POOL_TIMEOUT_S if pool_timeout_s is None else float(pool_timeout_s)
        if not 0.0 < wait_s <= 300.0:
            raise ValueError(f"pool_timeout_s must be within (0, 300] s, got {pool_timeout_s!r}")
        #: How long a session waits for a connection (and a request for an API slot), s.
        self.pool_timeout_s = wait_s
        # A pooled PostgreSQL connection may have been dropped by the server: ping it at
        # checkout.  A SQLite connection cannot be dropped (the file's side files are
        # checked at checkout instead, below), and a ping costs every session a round
        # trip to the driver's thread.
        kwargs: dict[str, object] = {"echo": echo, "pool_pre_ping": not url.startswith("sqlite")}
        path = make_url(url).database
        if path not in (None, "", ":memory:"):  # a pool of connections
            kwargs.update(pool_size=POOL_SIZE, max_overflow=POOL_OVERFLOW, pool_timeout=wait_s)
            if url.startswith("sqlite"):  # the WAL's side files checked at every checkout
                from backend.db.sqlitefiles import guarded_pool_for

                kwargs["poolclass"] = guarded_pool_for(str(path))
        if url.startswith("sqlite"):
            kwargs["connect_args"] = {"timeout": float(busy_timeout_s)}
        self.engine: AsyncEngine = create_async_engine(url, **kwargs)
        if url.startswith("sqlite"):
            event.listen(self.engine.sync_engine, "connect", _sqlite_pragmas)
        event.listen(self.engine.sync_engine, "do_connect", _connect_or_operational_error)
        if url.startswith("postgresql"):
            # Changes of models and views notify the plant's other processes (their indexes).
            from backend.db.changes import NotifyingSession

            self.sessionmaker = async_sessionmaker(
                self.engine, expire_on_commit=False, sync_session_class=NotifyingSession
            )
        else:
            self.sessionmaker = async_sessionmaker(self.engine, expire_on_commit=False)
        #: Taken by every REST request's database session (see :data:`API_SLOTS`).
        self.api_slots = asyncio.Semaphore(API_SLOTS)
        #: Called with the :data:`Changes` a session of :meth:`session` noted
        #: (:func:`changed`), once it ended: after its commit, and after a rollback too
        #: (dropping a cached answer for nothing only costs a read).
        self.on_change: list[Callable[[Changes], None]] = []

    @asynccontextmanager
    async def api_slot(self) -> AsyncIterator[None]:
        """Hold one of :data:`API_SLOTS`; :class:`DatabaseBusy` when none frees up within
        :attr:`pool_timeout_s` (the API answers 503, never a request hanging on)."""
        try:
            await asyncio.wait_for(self.api_slots.acquire(), self.pool_timeout_s)
        except TimeoutError:
            raise DatabaseBusy(
                f"all {API_SLOTS} database connections of the API were busy for "
                f"{self.pool_timeout_s:g} s"
            ) from None
        try:
            yield
        finally:
            self.api_slots.release()

    @asynccontextmanager
    async def session(self) -> AsyncIterator[AsyncSession]:
        """A session that commits on success and rolls back on any error (no partial rows)."""
        async with self.sessionmaker() as s:
            try:
                yield s
                await s.commit()
            except BaseException:
                await s.rollback()
                raise
            finally:
                self._changed(s.info.pop(_CHANGES, None))

    def _changed(self, noted: dict[str, set[int] | None] | None) -> None:
        if not noted:
            return
        changes = {k: None if v is None else frozenset(v) for k, v in noted.items()}
        for hook in list(self.on_change):
            try:
                hook(changes)
            except Exception:  # a cache's failure must not fail the committed write
                log.exception("change hook %r failed", hook)

    async def ping(self) -> bool:
        """True if the database answers a trivial query."""
        from sqlalchemy import text

        try:
            async with self.engine.connect() as conn:
                await conn.execute(text("SELECT 1"))
            return True
        except Exception:
            return False

    async def dispose(self) -> None:
        """Close every pooled connection."""
        await self.engine.dispose()


def _connect_or_operational_error(dialect: Any, _rec: Any, cargs: Any, cparams: Any) -> Any:
    """Open a DB-API connection; a socket error of the attempt (refused, unreachable, reset,
    timed out: ``OSError``) is raised as the driver's ``OperationalError``, as PEP 249 files
    it, so SQLAlchemy wraps it like any other "database unavailable" (asyncpg raises the
    bare ``OSError``, which would otherwise reach the API as a bug)."""
    dbapi = dialect.loaded_dbapi
    try:
        return dbapi.connect(*cargs, **cparams)
    except OSError as exc:
        raise dbapi.OperationalError(f"cannot connect to the database: {exc}") from exc


def _sqlite_pragmas(dbapi_conn, _record) -> None:
    cur = dbapi_conn.cursor()
    cur.execute("PRAGMA foreign_keys=ON")
    cur.execute("PRAGMA journal_mode=WAL")
    cur.close()
