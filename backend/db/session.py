"""Async engine and session factory."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from sqlalchemy import event
from sqlalchemy.engine import make_url
from sqlalchemy.ext.asyncio import (
    AsyncEngine,
    AsyncSession,
    async_sessionmaker,
    create_async_engine,
)

__all__ = ["API_SLOTS", "POOL_OVERFLOW", "POOL_SIZE", "Database"]

#: Pooled connections kept open, and how many more may be opened at busy times.
POOL_SIZE = 5
POOL_OVERFLOW = 10
#: Connections REST requests may hold at once (``backend.api.deps``); the rest of the pool
#: stays for the cell itself (inspections, teaching, jobs): under a surge of readers on a
#: starved machine the readers took all 15 and the inspection in progress waited for one
#: (``benchmarks/load.py``, ``tests/backend/test_bug_readers_starve_the_cell_of_connections.py``).
API_SLOTS = 10


class Database:
    """The engine and session factory of one process.

    SQLite gets foreign keys switched on (they are off by default) and a busy timeout so
    the API and the cell tasks can share the file.
    """

    def __init__(self, url: str, *, echo: bool = False, busy_timeout_s: float = 30.0) -> None:
        self.url = url
        kwargs: dict[str, object] = {"echo": echo, "pool_pre_ping": True}
        if make_url(url).database not in (None, "", ":memory:"):  # a pool of connections
            kwargs.update(pool_size=POOL_SIZE, max_overflow=POOL_OVERFLOW)
        if url.startswith("sqlite"):
            kwargs["connect_args"] = {"timeout": float(busy_timeout_s)}
        self.engine: AsyncEngine = create_async_engine(url, **kwargs)
        if url.startswith("sqlite"):
            event.listen(self.engine.sync_engine, "connect", _sqlite_pragmas)
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


def _sqlite_pragmas(dbapi_conn, _record) -> None:
    cur = dbapi_conn.cursor()
    cur.execute("PRAGMA foreign_keys=ON")
    cur.execute("PRAGMA journal_mode=WAL")
    cur.close()
