"""A short-lived, in-process cache of the console's hot database reads (model, cell and
inspection lists, the database part of ``/api/status``).

Under load each of those reads opened a database session for two or three queries, 7 to
11 ms of CPU per request (``benchmarks/load.py --route-cpu``), on the event loop that
also runs the cell.  An answer read in the last :data:`TTL_S` seconds is reused.  What
keeps it correct:

- **a commit of this process invalidates at once**: every ORM flush records the tables
  it wrote (``session.new``/``dirty``/``deleted``, and the table of a bulk
  ``insert``/``update``/``delete``; a textual statement other than a ``SELECT`` counts
  as "every table"); at
  ``after_commit`` the entries that read one of those tables are dropped, so a write
  through this cell's API is visible to the next read.  A rolled-back transaction
  invalidates nothing;
- a read that started before such a commit is not stored after it (a generation
  counter per table, as :mod:`backend.authcache` does);
- **another process** (a second ``visioncell serve`` of the plant on the same database,
  the ``visioncell`` CLI) is seen within :data:`TTL_S` seconds, when the entry expires;
- **roles are still checked per request**: the cache sits inside the handlers, after the
  role dependency has accepted the caller, and every entry carries the role it was read
  for; :meth:`ReadCache.get` refuses to return it to a weaker role.  Answers that depend
  on who asks are never cached;
- one read per key at a time: requests that miss while a read of the same answer is in
  flight wait for it (under load, a miss took long enough for every other console to
  miss too and open its own session);
- bounded: at most ``max_entries`` entries (the oldest go first); entries are the small
  JSON-ready dicts the routes answer.

**Refresh ahead.**  Under steady load every entry expired under the requests' feet: the
requests that arrived then waited on SQLite (behind the inspection's writes) for the one
read of the key.  A hit on an entry in the last :data:`REFRESH_AHEAD_FRACTION` of its TTL
(by :meth:`ReadCache.get_or_read` or :meth:`ReadCache.peek`) is answered from it and
starts one background re-read of the key with the read that made the entry, for the role
the entry was read for; the new entry replaces the old one before its ``until``.  The
rules above hold for it: it is registered as the key's read in flight (one per key;
requests that miss meanwhile share it), it is not stored when a commit wrote one of its
tables since it started, its ``until`` counts from its start, the old entry is never
served past its own ``until``.  At most :data:`MAX_REFRESHING` run at once (beyond it an
entry expires as without refresh); a failure is logged once per run of failures and leaves
the entry to expire; :meth:`ReadCache.close` (the runtime's shutdown, before the database
engine is disposed) cancels and awaits them.

:meth:`ReadCache.peek` gives the entry a request would be answered from, without reading
(the fast path of :mod:`backend.api.fastpath` answers from it, and keeps the answer's JSON
per entry: an :class:`Entry` is compared by identity).
"""

from __future__ import annotations

import asyncio
import logging
import threading
import time
import weakref
from collections.abc import Awaitable, Callable, Hashable, Iterable
from dataclasses import dataclass, field
from typing import Any, TypeVar

from sqlalchemy import event
from sqlalchemy import inspect as sa_inspect
from sqlalchemy.orm import ORMExecuteState, Session

from backend.db.models import Role
from backend.taskutil import BackgroundTasks, work_for_waiters

__all__ = [
    "ALL_TABLES",
    "MAX_ENTRIES",
    "MAX_REFRESHING",
    "REFRESH_AHEAD_FRACTION",
    "TTL_S",
    "Entry",
    "ReadCache",
]

log = logging.getLogger(__name__)

#: How long an answer is reused, seconds: the bound on seeing another process's writes.
TTL_S = 1.0
#: Most answers kept.
MAX_ENTRIES = 512
#: The last part of an entry's TTL in which a hit starts its background re-read.  A re-read
#: under load waits for the database behind the inspection's writes and the API's
#: connection slots (read p99 117-817 ms on the database routes, docs/plant.md "Load"):
#: the window must outlast that for the new entry to be in place before the old one's
#: ``until``; a wider one reads a key more often (under steady hits once per
#: ``(1 - fraction) * TTL``: 0.4 reads it every 0.6 TTL instead of every TTL).
REFRESH_AHEAD_FRACTION = 0.4
#: Most background re-reads in flight over one cache: each holds one of the API's 10
#: database connection slots (``backend.db.session.API_SLOTS``), most stay for requests.
MAX_REFRESHING = 4
#: Stands for "every table" (a statement whose table is not known).
ALL_TABLES = "*"
_PENDING = "visioncell_readcache_tables"

T = TypeVar("T")

_caches: weakref.WeakSet[ReadCache] = weakref.WeakSet()


@dataclass(frozen=True)
class _Flight:
    """A read in progress: its loop, the role and tables it reads for, the generation
    it started at, and the future its waiters share."""

    loop: asyncio.AbstractEventLoop
    role: Role
    tables: frozenset[str]
    gen: tuple[int, ...]
    future: asyncio.Future[Any]


@dataclass(frozen=True, eq=False)
class Entry:
    """One cached answer.  Equal only to itself: a new read makes a new entry, so an
    entry's identity stands for its answer (what the fast path keys its JSON on)."""

    #: The cache's clock (``time.monotonic`` by default) after which it is not served.
    until: float
    #: The role it was read for (served to that role and stronger ones only).
    role: Role
    #: The tables it read (a commit writing one of them drops it).
    tables: frozenset[str]
    #: The answer, shared: not to be mutated.
    value: Any
    #: The read that made it (its refresh ahead reads with it; None: never refreshed).
    read: Callable[[], Awaitable[Any]] | None = field(default=None, repr=False)


def _monotonic() -> float:
    # looked up at each call, so a test may also replace the module's ``time``
    return time.monotonic()


class ReadCache:
    """Answers by key for ``ttl_s`` seconds, dropped when a table they read is written
    (see the module doc).

    Parameters
    ----------
    ttl_s : float
        Reuse time, seconds, in [0, 10]; 0 turns the cache off (every read is computed).
    max_entries : int
        Most entries kept, 1..100000.
    refresh_ahead : bool
        Re-read an entry in the background when it is hit in the last
        :data:`REFRESH_AHEAD_FRACTION` of its TTL (see the module doc); False: entries
        expire and the next request reads.
    clock : callable, optional
        Monotonic seconds the TTL is counted in (default: ``time.monotonic``); a test
        gives its own, so an entry's age does not depend on how busy the machine is.
    """

    def __init__(
        self,
        *,
        ttl_s: float = TTL_S,
        max_entries: int = MAX_ENTRIES,
        refresh_ahead: bool = True,
        clock: Callable[[], float] | None = None,
    ) -> None:
        if isinstance(ttl_s, bool) or not isinstance(ttl_s, int | float):
            raise TypeError(f"ttl_s must be a number, got {ttl_s!r}")
        if not 0.0 <= float(ttl_s) <= 10.0:
            raise ValueError(f"ttl_s must be within 0..10 s, got {ttl_s!r}")
        if isinstance(max_entries, bool) or not isinstance(max_entries, int):
            raise TypeError(f"max_entries must be an int, got {max_entries!r}")
        if not 1 <= max_entries <= 100_000:
            raise ValueError(f"max_entries must be within 1..100000, got {max_entries!r}")
        if not isinstance(refresh_ahead, bool):
            raise TypeError(f"refresh_ahead must be a bool, got {refresh_ahead!r}")
        self.refresh_ahead = refresh_ahead
        self._clock = clock if clock is not None else _monotonic
        self.ttl_s = float(ttl_s)
        self.max_entries = max_entries
        self._entries: dict[Hashable, Entry] = {}
        self._lock = threading.Lock()
        self._generation: dict[str, int] = {}
        self._inflight: dict[Hashable, _Flight] = {}
        #: Answers served from an entry, read, and shared with a read in flight.
        self.hits = 0
        self.misses = 0
        self.shared = 0
        #: Background re-reads started, and those that failed.
        self.refreshes = 0
        self.refresh_failures = 0
        self._background = BackgroundTasks(MAX_REFRESHING)
        self._failing = False  # the last re-read failed (logged once until one succeeds)
        #: Entries whose re-read failed: left to expire, not re-read on every later hit.
        self._not_again: weakref.WeakSet[Entry] = weakref.WeakSet()
        _caches.add(self)

    def _gen(self, tables: Iterable[str]) -> tuple[int, ...]:
        star = self._generation.get(ALL_TABLES, 0)
        return (star, *(self._generation.get(t, 0) for t in sorted(tables)))

    async def get_or_read(
        self, key: Hashable, *, role: Role, tables: Iterable[str],
        read: Callable[[], Awaitable[T]],
    ) -> T:  # fmt: skip
        """The cached answer of ``key`` when fresh and read for a role no stronger than
        ``role``; otherwise ``await read()``, stored for ``ttl_s`` seconds as read for
        ``role``, to be dropped when one of ``tables`` is written.

        The caller has checked ``role`` may read this answer; the value is returned as
        stored (callers must not mutate it)."""
        if not isinstance(role, Role):
            raise TypeError(f"role must be a Role, got {role!r}")
        deps = frozenset(tables)
        if not deps or not all(isinstance(t, str) and t for t in deps):
            raise ValueError(f"tables must name at least one table, got {tables!r}")
        hash(key)  # a TypeError now, not inside the lock
        now = self._clock()
        with self._lock:
            e = self._fresh(key, role, deps, now)
            gen = self._gen(deps)
        if e is not None:
            self._refresh_if_due(key, e, now)
            return e.value
        if self.ttl_s <= 0:
            self.misses += 1
            return await read()
        # One read per key at a time: callers that miss while it is in flight share its
        # answer (when read for a role no stronger than theirs, and not made stale by a
        # commit since it started) instead of each opening a session of its own.
        loop = asyncio.get_running_loop()
        flight = self._inflight.get(key)
        if (
            flight is not None and flight.loop is loop and flight.tables == deps
            and role >= flight.role and flight.gen == gen
        ):  # fmt: skip
            self.shared += 1
            try:
                return await asyncio.shield(flight.future)
            except asyncio.CancelledError:
                task = asyncio.current_task()
                if not flight.future.cancelled() or (task is not None and task.cancelling()):
                    raise  # this caller was cancelled, not the read it waited for
            # The caller that read was cancelled (its client went away): read here.
            return await self.get_or_read(key, role=role, tables=deps, read=read)
        self.misses += 1
        mine = _Flight(loop, role, deps, gen, loop.create_future())
        self._inflight[key] = mine
        try:
            value = await work_for_waiters(mine.future, read())
        finally:
            if self._inflight.get(key) is mine:
                del self._inflight[key]
        mine.future.set_result(value)
        self._store(key, gen, Entry(now + self.ttl_s, role, deps, value, read))
        return value

    def _store(self, key: Hashable, gen: tuple[int, ...], entry: Entry) -> None:
        """Keep ``entry``, read from generation ``gen``, unless a commit wrote one of its
        tables since (the generation rule) or a later read of the key is kept already."""
        with self._lock:
            if self._gen(entry.tables) != gen:  # something it read was written meanwhile
                return
            old = self._entries.get(key)
            if old is not None and old.until > entry.until:
                return
            self._entries.pop(key, None)
            self._entries[key] = entry
            while len(self._entries) > self.max_entries:
                del self._entries[next(iter(self._entries))]

    def _refresh_if_due(self, key: Hashable, e: Entry, now: float) -> None:
        """Start the background re-read of ``key`` when ``e``, just hit, is in the last
        :data:`REFRESH_AHEAD_FRACTION` of its TTL, no read of the key is in flight and
        fewer than :data:`MAX_REFRESHING` re-reads run."""
        if (
            not self.refresh_ahead or self._background.closed or e.read is None
            or now < e.until - REFRESH_AHEAD_FRACTION * self.ttl_s
            or key in self._inflight or self._background.full()
            or e in self._not_again
        ):  # fmt: skip
            return
        try:
            loop = asyncio.get_running_loop()
        except RuntimeError:  # not called from a coroutine: nowhere to run it
            return
        with self._lock:
            gen = self._gen(e.tables)
        flight = _Flight(loop, e.role, e.tables, gen, loop.create_future())
        self._inflight[key] = flight
        self._background.spawn(
            loop, self._refresh(key, e, flight), name=f"read-cache refresh {key!r}"
        )
        self.refreshes += 1

    async def _refresh(self, key: Hashable, old: Entry, flight: _Flight) -> None:
        """The background re-read of ``key`` (``old.read``, for ``old.role``), shared with
        the requests that miss meanwhile; never raises but its cancellation."""
        assert old.read is not None
        start = self._clock()
        try:
            value = await old.read()
        except asyncio.CancelledError:
            flight.future.cancel()  # its waiters read themselves (get_or_read)
            raise
        except BaseException as exc:
            flight.future.set_exception(exc)
            flight.future.exception()  # retrieved: no "never retrieved" warning
            if not isinstance(exc, Exception):
                raise
            self.refresh_failures += 1
            self._not_again.add(old)
            if not self._failing:
                self._failing = True
                log.warning(
                    "read cache: background re-read of %r failed (logged once until one "
                    "succeeds; the entry expires as usual): %r", key, exc,
                )  # fmt: skip
            return
        finally:
            if self._inflight.get(key) is flight:
                del self._inflight[key]
        flight.future.set_result(value)
        if self._failing:
            self._failing = False
            log.info("read cache: background re-reads succeed again")
        self._store(
            key, flight.gen, Entry(start + self.ttl_s, old.role, old.tables, value, old.read)
        )

    @property
    def refreshing(self) -> int:
        """Background re-reads in flight."""
        return len(self._background)

    def open(self) -> None:
        """Let background re-reads start again after :meth:`close` (a runtime entered again)."""
        self._background.open()

    async def close(self) -> None:
        """Cancel the background re-reads and wait for their end (those of this event
        loop; another loop's are only cancelled), start none until :meth:`open`, and drop
        every entry (their reads hold the database about to be disposed)."""
        await self._background.close()
        self.invalidate({ALL_TABLES})

    def _fresh(self, key: Hashable, role: Role, deps: frozenset[str], now: float) -> Entry | None:
        """The entry of ``key`` if it may answer ``role`` now (counted as a hit); the
        caller holds the lock."""
        e = self._entries.get(key)
        if e is not None and now < e.until and e.tables == deps and role >= e.role:
            self.hits += 1
            return e
        return None

    def peek(self, key: Hashable, *, role: Role, tables: Iterable[str]) -> Entry | None:
        """The entry :meth:`get_or_read` would answer ``key`` from now for ``role`` (the
        same freshness, tables and role rule), or None; never waits.  A hit is counted,
        and starts the entry's refresh ahead as in :meth:`get_or_read`."""
        if not isinstance(role, Role):
            raise TypeError(f"role must be a Role, got {role!r}")
        deps = tables if isinstance(tables, frozenset) else frozenset(tables)
        now = self._clock()
        with self._lock:
            e = self._fresh(key, role, deps, now)
        if e is not None:
            self._refresh_if_due(key, e, now)
        return e

    def invalidate(self, tables: Iterable[str]) -> int:
        """Drop the entries that read one of ``tables`` (:data:`ALL_TABLES`: every entry);
        a read in progress is not stored after this.  Returns how many were dropped."""
        names = set(tables)
        with self._lock:
            for t in names:
                self._generation[t] = self._generation.get(t, 0) + 1
            if ALL_TABLES in names:
                n = len(self._entries)
                self._entries.clear()
                return n
            gone = [k for k, e in self._entries.items() if e.tables & names]
            for k in gone:
                del self._entries[k]
            return len(gone)

    def __len__(self) -> int:
        with self._lock:
            return len(self._entries)


def invalidate_all(tables: Iterable[str]) -> None:
    """:meth:`ReadCache.invalidate` on every cache of this process."""
    names = set(tables)
    for cache in list(_caches):
        cache.invalidate(names)


def _record(session: Session, tables: Iterable[str]) -> None:
    session.info.setdefault(_PENDING, set()).update(tables)


def _table_of(obj: Any) -> str:
    table = sa_inspect(obj).mapper.local_table
    return str(getattr(table, "name", ALL_TABLES))


@event.listens_for(Session, "after_flush")
def _after_flush(session: Session, _ctx: Any) -> None:
    written = {_table_of(o) for o in (*session.new, *session.dirty, *session.deleted)}
    if written:
        _record(session, written)


def _is_textual_read(statement: Any) -> bool:
    """A ``text("SELECT ...")`` statement (its table is not known, but it writes none)."""
    sql = getattr(statement, "text", None)
    return isinstance(sql, str) and sql.lstrip().lower().startswith("select")


@event.listens_for(Session, "do_orm_execute")
def _do_orm_execute(state: ORMExecuteState) -> None:
    if state.is_select or _is_textual_read(state.statement):
        return
    table = getattr(state.statement, "table", None)
    name = getattr(table, "name", None)
    _record(state.session, {name if isinstance(name, str) else ALL_TABLES})


@event.listens_for(Session, "after_commit")
def _after_commit(session: Session) -> None:
    tables = session.info.pop(_PENDING, None)
    if tables:
        invalidate_all(tables)


@event.listens_for(Session, "after_rollback")
def _after_rollback(session: Session) -> None:
    session.info.pop(_PENDING, None)
