"""The runtime's two small caches: the console's hot reads and the token sign-ins.

Both are :class:`cachetools.TTLCache` (bounded, least recently used first out, entries
expire after a TTL counted by an injectable clock).  They are kept correct by explicit
invalidation, not by watching the database:

- the services that write call :func:`backend.db.session.changed` (a topic: a table name,
  or :data:`USERS` for sign-ins) in the transaction; when its session ends, the
  :class:`~backend.db.session.Database` calls the runtime's hook, which drops what the
  caches read of those topics (:meth:`ReadCache.invalidate`, :meth:`AuthCache.forget_users`);
- a change of sign-ins (a token revoked, a user disabled, deleted or given another role)
  is noted with :func:`users_changed`, which on PostgreSQL also sends
  ``pg_notify(AUTH_CHANNEL, ...)`` in the transaction: every process of the plant hears it
  once the transaction committed (:class:`backend.authsync.AuthSync`) and forgets those
  users at once;
- a read that started before an invalidation is not stored after it (a generation per
  topic), so a stale answer cannot outlive the write that made it stale;
- other processes on SQLite (another ``visioncell serve``, the CLI): the TTL bounds how
  long a change stays unseen here;
- roles are still checked per request: the read cache sits inside the handlers, after the
  role dependency accepted the caller, and an entry read for a role is served to that
  role and stronger ones only;
- a successful sign-in is also noted in :attr:`AuthCache.known` (the emergency stop's
  sign-in from memory, :mod:`backend.knowntokens`); failed sign-ins are never cached.
"""

from __future__ import annotations

import asyncio
import os
import threading
import time
from collections.abc import Awaitable, Callable, Hashable, Iterable
from dataclasses import dataclass
from datetime import datetime
from typing import Any, TypeVar, cast

from cachetools import TTLCache
from sqlalchemy import text

from backend.db.models import Role, User
from backend.db.session import Changes, changed
from backend.db.types import utcnow
from backend.knowntokens import KnownTokens

__all__ = [
    "AUTH_CHANNEL",
    "USERS",
    "Answer",
    "AuthCache",
    "Lookup",
    "ReadCache",
    "SignIn",
    "parse_payload",
    "users_changed",
]

#: The topic of sign-in changes (users and their tokens).
USERS = "users"
#: The notification channel of sign-in changes (a PostgreSQL identifier).
AUTH_CHANNEL = "visioncell_auth"
#: Most user ids one notification lists (PostgreSQL caps a payload at 8000 bytes).
_MAX_IDS = 500

T = TypeVar("T")

#: A successful sign-in read from the database: the user and the token's expiry.
SignIn = tuple[User, datetime | None]
#: Reads a token's sign-in from the database (None: refused).
Lookup = Callable[[], Awaitable[SignIn | None]]


async def users_changed(session: Any, user_ids: Iterable[int] | None) -> None:
    """Note in ``session``'s transaction that the sign-ins of ``user_ids`` changed (None:
    any user): this process's caches forget them when the session ends; on PostgreSQL the
    other processes hear it when the transaction commits."""
    ids = None if user_ids is None else frozenset(int(i) for i in user_ids)
    changed(session, USERS, ids)
    if session.get_bind().dialect.name == "postgresql":
        listed = "*" if ids is None or len(ids) > _MAX_IDS else ",".join(map(str, sorted(ids)))
        await session.execute(
            text("SELECT pg_notify(:channel, :payload)"),
            {"channel": AUTH_CHANNEL, "payload": f"pid={os.getpid()};users={listed}"},
        )


def parse_payload(payload: str) -> frozenset[int] | None:
    """The user ids of a notification's payload (None: any user, also for a payload this
    version cannot read: forgetting too much only costs a database read)."""
    fields = dict(p.split("=", 1) for p in payload.split(";") if "=" in p)
    users = fields.get("users", "*")
    if users == "*" or len(users) > 8000:
        return None
    try:
        ids = frozenset(int(u) for u in users.split(",") if u)
    except ValueError:
        return None
    return ids if ids else None


def _check(ttl_s: float, max_entries: int, max_ttl_s: float) -> None:
    if isinstance(ttl_s, bool) or not isinstance(ttl_s, int | float):
        raise TypeError(f"ttl_s must be a number, got {ttl_s!r}")
    if not 0.0 <= float(ttl_s) <= max_ttl_s:
        raise ValueError(f"ttl_s must be within 0..{max_ttl_s:g} s, got {ttl_s!r}")
    if isinstance(max_entries, bool) or not isinstance(max_entries, int):
        raise TypeError(f"max_entries must be an int, got {max_entries!r}")
    if not 1 <= max_entries <= 1_000_000:
        raise ValueError(f"max_entries must be within 1..1000000, got {max_entries!r}")


@dataclass(frozen=True, eq=False)
class Answer:
    """One kept answer.  Equal only to itself: a new read makes a new one (the fast path
    of :mod:`backend.api.fastpath` keeps its rendered bytes per answer)."""

    #: The role it was read for (served to that role and stronger ones only).
    role: Role
    #: The topics it read.
    topics: frozenset[str]
    #: The answer, shared: not to be mutated.
    value: Any


@dataclass(frozen=True)
class _Flight:
    loop: asyncio.AbstractEventLoop
    tag: Any
    future: asyncio.Future[Any]


class _Flights:
    """One read per key at a time: callers that miss while a read of their key is in
    flight share its answer (or its error), when ``may_share`` accepts its ``tag``; a
    caller whose reader went away (cancelled) reads itself."""

    def __init__(self) -> None:
        self._flights: dict[Hashable, _Flight] = {}
        #: Callers that shared a read in flight.
        self.shared = 0

    async def read(
        self, key: Hashable, tag: Any, may_share: Callable[[Any], bool],
        read: Callable[[], Awaitable[T]],
    ) -> T:  # fmt: skip
        loop = asyncio.get_running_loop()
        flight = self._flights.get(key)
        if flight is not None and flight.loop is loop and may_share(flight.tag):
            self.shared += 1
            try:
                return cast(T, await asyncio.shield(flight.future))
            except asyncio.CancelledError:
                if not flight.future.cancelled():
                    raise  # this caller was cancelled, not the read it waited for
        mine = _Flight(loop, tag, loop.create_future())
        self._flights[key] = mine
        try:
            value = await read()
        except asyncio.CancelledError:
            mine.future.cancel()
            raise
        except BaseException as exc:
            mine.future.set_exception(exc)
            mine.future.exception()  # marked retrieved: its waiters, if any, get it too
            raise
        finally:
            if self._flights.get(key) is mine:
                del self._flights[key]
        mine.future.set_result(value)
        return value

    def clear(self) -> None:
        self._flights.clear()


class ReadCache:
    """Answers by key for ``ttl_s`` seconds, dropped when a topic they read is written.

    Parameters
    ----------
    ttl_s : float
        Reuse time, seconds, in [0, 10]; 0 turns the cache off.
    max_entries : int
        Most answers kept (the least recently used go first).
    clock : callable
        Monotonic seconds the TTL is counted in (a test gives its own).
    """

    def __init__(
        self, *, ttl_s: float = 1.0, max_entries: int = 512,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:  # fmt: skip
        _check(ttl_s, max_entries, 10.0)
        self._answers: TTLCache[Hashable, Answer] = TTLCache(max_entries, ttl_s, timer=clock)
        self._generation: dict[str, int] = {}
        self._epoch = 0  # grows with every clear()
        self._flights = _Flights()
        #: Answers served from memory, and reads made (and :attr:`shared`).
        self.hits = 0
        self.misses = 0

    @property
    def ttl_s(self) -> float:
        """Reuse time, seconds (fixed when the cache is made)."""
        return float(self._answers.ttl)

    def _gen(self, topics: frozenset[str]) -> tuple[int, ...]:
        return (self._epoch, *(self._generation.get(t, 0) for t in sorted(topics)))

    async def get_or_read(
        self, key: Hashable, *, role: Role, topics: Iterable[str],
        read: Callable[[], Awaitable[T]],
    ) -> T:  # fmt: skip
        """The answer of ``key`` read for a role no stronger than ``role`` within the TTL
        and since the last change of ``topics``; else ``await read()``, kept.  Callers
        that miss while a read of ``key`` for a role no stronger than theirs is in flight
        share it.  The value is shared: not to be mutated."""
        if not isinstance(role, Role):
            raise TypeError(f"role must be a Role, got {role!r}")
        deps = frozenset(topics)
        if not deps or not all(isinstance(t, str) and t for t in deps):
            raise ValueError(f"topics must name at least one topic, got {topics!r}")
        if self.ttl_s <= 0:
            self.misses += 1
            return await read()
        found = self._answers.get(key)
        if found is not None and found.topics == deps and role >= found.role:
            self.hits += 1
            return found.value
        gen = self._gen(deps)

        async def read_and_keep() -> T:
            self.misses += 1
            value = await read()
            if self._gen(deps) == gen:  # nothing it read was written meanwhile
                self._answers[key] = Answer(role, deps, value)
            return value

        def may_share(tag: tuple[Role, tuple[int, ...]]) -> bool:
            return role >= tag[0] and tag[1] == gen

        return await self._flights.read(key, (role, gen), may_share, read_and_keep)

    def peek(self, key: Hashable, *, role: Role, topics: Iterable[str]) -> Answer | None:
        """The answer :meth:`get_or_read` would give ``key`` now for ``role`` without
        reading (the same TTL, topics and role rule; counted as a hit), or None."""
        found = self._answers.get(key)
        if (
            found is None or self.ttl_s <= 0 or role < found.role
            or found.topics != frozenset(topics)
        ):  # fmt: skip
            return None
        self.hits += 1
        return found

    @property
    def shared(self) -> int:
        """Callers that shared a read in flight instead of reading."""
        return self._flights.shared

    def invalidate(self, topics: Iterable[str]) -> int:
        """Drop the answers that read one of ``topics``; a read in progress is not kept
        after this.  Returns how many were dropped."""
        names = set(topics)
        for t in names:
            self._generation[t] = self._generation.get(t, 0) + 1
        gone = [k for k, a in list(self._answers.items()) if a.topics & names]
        for k in gone:
            self._answers.pop(k, None)
        return len(gone)

    def clear(self) -> None:
        """Drop every answer (a read in progress is not kept)."""
        self._epoch += 1
        self._flights.clear()
        self._answers.clear()

    def on_change(self, changes: Changes) -> None:
        """The database's hook: drop what was read of the changed topics."""
        self.invalidate(changes)

    def __len__(self) -> int:
        return len(self._answers)


@dataclass(frozen=True)
class _SignedIn:
    user: tuple[int, str, str, datetime]  # id, name, role, created_at
    expires_at: datetime | None


def _row(user: User) -> tuple[int, str, str, datetime]:
    return (int(user.id), str(user.name), str(user.role), user.created_at)


def _user_of(e: _SignedIn) -> User | None:
    """A detached user of ``e`` for one request (None: the token expired since)."""
    if e.expires_at is not None and e.expires_at <= utcnow():
        return None
    uid, name, role, created = e.user
    return User(id=uid, name=name, role=role, disabled=False, created_at=created)


def _aware(at: datetime | None) -> datetime | None:
    return at.replace(tzinfo=utcnow().tzinfo) if at is not None and at.tzinfo is None else at


class AuthCache:
    """Successful sign-ins by token hash (the HMAC, never the token) for ``ttl_s`` seconds.

    Parameters
    ----------
    ttl_s : float
        Reuse time, seconds, in [0, 60]; 0: every sign-in reads the database.
    max_entries : int
        Most tokens kept (the least recently used go first).
    clock : callable
        Monotonic seconds the TTL is counted in (a test gives its own).
    known : KnownTokens, optional
        Where every successful sign-in read from the database is also noted (the
        emergency stop's sign-in from memory).
    """

    def __init__(
        self, *, ttl_s: float = 2.0, max_entries: int = 10_000,
        clock: Callable[[], float] = time.monotonic, known: KnownTokens | None = None,
    ) -> None:  # fmt: skip
        _check(ttl_s, max_entries, 60.0)
        self.known = known
        self._entries: TTLCache[str, _SignedIn] = TTLCache(max_entries, ttl_s, timer=clock)
        self._lock = threading.Lock()  # the 3D view signs in from viser's threads
        #: Grows with every change of sign-ins: a lookup started before one is not kept.
        self.generation = 0
        #: Sign-ins read from the database.
        self.lookups = 0
        self._flights = _Flights()

    @property
    def ttl_s(self) -> float:
        """Reuse time, seconds (fixed when the cache is made)."""
        return float(self._entries.ttl)

    def get(self, token_hash: str) -> User | None:
        """A detached copy of the user ``token_hash`` signs in, if cached and the token
        not past its expiry (None: ask the database)."""
        with self._lock:
            e = self._entries.get(token_hash)
            if e is not None and e.expires_at is not None and e.expires_at <= utcnow():
                self._entries.pop(token_hash, None)
                e = None
        return None if e is None else _user_of(e)

    async def sign_in(self, token_hash: str, lookup: Lookup) -> User | None:
        """The user ``token_hash`` signs in: cached, else ``lookup()`` (kept when it
        succeeds and no sign-in changed meanwhile), shared by the requests of the same
        token that miss while it runs.  None: refused (never kept)."""
        user = self.get(token_hash)
        if user is not None:
            return user
        generation = self.generation

        async def look_up() -> _SignedIn | None:
            self.lookups += 1
            found = await lookup()
            if found is None:
                return None
            self.put(token_hash, found[0], found[1], generation=generation)
            return _SignedIn(_row(found[0]), _aware(found[1]))

        got = await self._flights.read(
            token_hash, generation, lambda g: g == self.generation, look_up
        )
        return None if got is None else _user_of(got)

    @property
    def shared(self) -> int:
        """Sign-ins that shared a lookup in flight instead of looking up."""
        return self._flights.shared

    def put(
        self, token_hash: str, user: User, expires_at: datetime | None, *, generation: int
    ) -> None:
        """Keep a successful sign-in read from the database when :attr:`generation` was
        ``generation`` (a sign-in changed since: not kept, not noted)."""
        if user.disabled or generation != self.generation:
            return
        if self.known is not None:
            self.known.note(token_hash, user_id=int(user.id), user=user.name, role=user.role)
        if self.ttl_s <= 0:
            return
        with self._lock:
            self._entries[token_hash] = _SignedIn(_row(user), _aware(expires_at))

    def forget_users(self, user_ids: Iterable[int] | None) -> int:
        """Drop the sign-ins of ``user_ids`` (None: all) here and in :attr:`known`; a
        lookup in progress is not kept after this.  Returns how many were dropped."""
        ids = None if user_ids is None else frozenset(user_ids)
        if self.known is not None:
            self.known.forget_users(ids)
        with self._lock:
            self.generation += 1
            gone = [k for k, e in list(self._entries.items()) if ids is None or e.user[0] in ids]
            for k in gone:
                self._entries.pop(k, None)
        return len(gone)

    def clear(self) -> None:
        """Forget every cached sign-in (:attr:`known` keeps its tokens)."""
        with self._lock:
            self.generation += 1
            self._entries.clear()

    def on_change(self, changes: Changes) -> None:
        """The database's hook: forget the users whose sign-ins changed."""
        if USERS in changes:
            self.forget_users(changes[USERS])

    def __len__(self) -> int:
        with self._lock:
            return len(self._entries)
