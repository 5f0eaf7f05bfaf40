"""The runtime's two small caches: the console's hot reads and the token sign-ins.

This module keeps the sign-in cache (:class:`AuthCache`) and the notes of sign-in changes;
the read cache is :class:`backend.readcache.ReadCache` (named here too).  Both are
:class:`cachetools.TTLCache` (bounded, least recently used first out, entries expire after
a TTL counted by an injectable clock).  They are kept correct by explicit invalidation, not
by watching the database:

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

import os
import threading
import time
from collections.abc import Awaitable, Callable, Iterable
from dataclasses import dataclass
from datetime import datetime
from typing import Any

from cachetools import TTLCache
from sqlalchemy import text

from backend.cachebase import Flights, check_limits
from backend.db.models import User
from backend.db.session import Changes, changed
from backend.db.types import utcnow
from backend.knowntokens import KnownTokens
from backend.readcache import Answer, ReadCache

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
        check_limits(ttl_s, max_entries, 60.0)
        self.known = known
        self._entries: TTLCache[str, _SignedIn] = TTLCache(max_entries, ttl_s, timer=clock)
        self._lock = threading.Lock()  # the 3D view signs in from viser's threads
        #: Grows with every change of sign-ins: a lookup started before one is not kept.
        self.generation = 0
        #: Sign-ins read from the database.
        self.lookups = 0
        self._flights = Flights()

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
