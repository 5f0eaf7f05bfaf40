"""A short-lived, in-process cache of successful token sign-ins.

Checking a token took one database session with two queries per request (about 10 ms of
CPU each, most of an authenticated read: ``benchmarks/load.py``).  A token seen valid in
the last :data:`TTL_S` seconds is accepted again from this cache, keyed by its HMAC (never
the token).  What keeps it safe:

- any commit of this process that changes a user or a token (revocation, role change,
  deletion, disabling) clears every cache at once (session events, below), so a change
  made through this cell's API or CLI run in-process applies to the next request;
- an entry carries the token's expiry, checked on every hit;
- on PostgreSQL, a commit that revokes, changes or deletes a token or a user also sends
  ``pg_notify(AUTH_CHANNEL, "pid=P;users=ID,ID")`` inside its transaction (``*``: users
  not known, a bulk statement); every process of the plant LISTENs
  (:class:`backend.authsync.AuthSync`) and drops that user's entries at once.  PostgreSQL
  delivers a notification only once its transaction committed;
- otherwise (SQLite, the listening connection lost) a change made by another process
  (another cell of the plant, the ``visioncell`` CLI) applies here within :data:`TTL_S`
  seconds, when the entry expires;
- failed sign-ins are never cached (each one still reaches the database and the throttle).

Every successful sign-in read from the database is also noted in :attr:`AuthCache.known`
(:class:`backend.knowntokens.KnownTokens`, for an hour: the emergency stop's sign-in from
memory); a commit of this process that changes a user's sign-ins drops that user's tokens
from it, as does :meth:`AuthCache.forget_users` (another process's notification).

**One lookup per token at a time, refreshed ahead** (:meth:`AuthCache.sign_in`).  Under
load (the console's clients often share one token) every request that arrived when an
entry had expired did its own database sign-in.  Now requests whose token has no entry
share the one lookup in flight for it (when it started after the last user or token change
of this process: :attr:`AuthCache.generation`; each still gets its own refusal, counted by
the throttle), and a hit in the last :data:`REFRESH_AHEAD_FRACTION` of an entry's TTL
starts one background lookup of that token, which re-checks it in the database: still
valid, the entry is replaced (its TTL counted from the lookup's start); revoked, expired
or disabled, the entry is dropped.  So a token revoked elsewhere stops working within
:data:`TTL_S` seconds of the revocation as before (an entry is never served past its
``until``, and every entry was read at most :data:`TTL_S` seconds before).  At most
:data:`MAX_REFRESHING` lookups run in the background; a failed one is logged once per run
of failures and leaves the entry to expire; :meth:`AuthCache.close` cancels them.
"""

from __future__ import annotations

import asyncio
import logging
import threading
import time
import weakref
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from datetime import datetime
from typing import Any

from sqlalchemy import event, text
from sqlalchemy import inspect as sa_inspect
from sqlalchemy.orm import ORMExecuteState, Session

from backend.db.models import ApiToken, User
from backend.db.types import utcnow
from backend.knowntokens import KnownTokens
from backend.taskutil import BackgroundTasks, work_for_waiters

__all__ = [
    "AUTH_CHANNEL",
    "AUTH_USERS_OPTION",
    "MAX_ENTRIES",
    "MAX_REFRESHING",
    "REFRESH_AHEAD_FRACTION",
    "TTL_S",
    "AuthCache",
    "Lookup",
    "SignIn",
    "parse_payload",
]

log = logging.getLogger(__name__)

#: How long a successful sign-in is reused, seconds.
TTL_S = 2.0
#: Most tokens kept (the oldest entries go first beyond it).
MAX_ENTRIES = 10_000
#: The last part of an entry's TTL in which a hit starts its background lookup: longer than
#: a lookup takes under load (one query on SQLite behind the inspection's writes, tens to
#: hundreds of ms), so the entry is replaced before it expires; a wider window looks a busy
#: token up more often (once per ``(1 - fraction) * TTL_S``: 1.2 s instead of 2 s).
REFRESH_AHEAD_FRACTION = 0.4
#: Most background lookups in flight (each holds one of the API's database slots).
MAX_REFRESHING = 4
_WATCHED = frozenset({"users", "api_tokens"})
_FLAG = "visioncell_auth_change"
#: Users whose sign-ins a transaction changed (a set of ids, or None: any user).
_USERS = "visioncell_auth_users"
#: The same users, kept from ``before_commit`` to ``after_commit`` (for the known tokens).
_FORGET = "visioncell_auth_forget"
#: The notification channel of sign-in changes (a PostgreSQL identifier).
AUTH_CHANNEL = "visioncell_auth"
#: Execution option of a bulk ``update``/``delete`` of users or tokens naming the user ids
#: it touches (``backend.auth.revoke_tokens``); without it a notification says "any user".
AUTH_USERS_OPTION = "visioncell_auth_users"
#: Most user ids one notification lists (PostgreSQL caps a payload at 8000 bytes).
_MAX_IDS = 500
_caches: weakref.WeakSet[AuthCache] = weakref.WeakSet()

#: A successful sign-in read from the database: the user and the token's expiry.
SignIn = tuple[User, datetime | None]
#: Reads a token's sign-in from the database (None: refused: unknown, revoked, expired,
#: disabled).
Lookup = Callable[[], Awaitable[SignIn | None]]
_UserRow = tuple[int, str, str, bool, datetime]


@dataclass(frozen=True)
class _Entry:
    until: float
    expires_at: datetime | None
    user: _UserRow


@dataclass(frozen=True)
class _Flight:
    """A lookup in progress: its loop, the :attr:`AuthCache.generation` it started at and
    the future its waiters share (the user as a row, and the expiry; or None)."""

    loop: asyncio.AbstractEventLoop
    generation: int
    future: asyncio.Future[tuple[_UserRow, datetime | None] | None]


def _monotonic() -> float:
    # looked up at each call, so a test may also replace the module's ``time``
    return time.monotonic()


def _row(user: User) -> _UserRow:
    return (int(user.id), str(user.name), str(user.role), bool(user.disabled), user.created_at)


def _user(row: _UserRow) -> User:
    uid, name, role, disabled, created = row
    return User(id=uid, name=name, role=role, disabled=disabled, created_at=created)


def _aware(expires_at: datetime | None) -> datetime | None:
    if expires_at is not None and expires_at.tzinfo is None:
        return expires_at.replace(tzinfo=utcnow().tzinfo)
    return expires_at


class AuthCache:
    """Successful sign-ins by token hash for ``ttl_s`` seconds (see the module doc).

    Parameters
    ----------
    ttl_s : float
        Reuse time, seconds, in [0, 60]; 0: every sign-in reads the database.
    max_entries : int
        Most tokens kept, 1..1e6.
    refresh_ahead : bool
        Share a token's lookup in flight and refresh an entry hit in the last
        :data:`REFRESH_AHEAD_FRACTION` of its TTL in the background (see the module doc);
        False: every request that misses looks its token up itself.
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
        if not 0.0 <= float(ttl_s) <= 60.0:
            raise ValueError(f"ttl_s must be within 0..60 s, got {ttl_s!r}")
        if not 1 <= int(max_entries) <= 1_000_000:
            raise ValueError(f"max_entries must be within 1..1e6, got {max_entries!r}")
        if not isinstance(refresh_ahead, bool):
            raise TypeError(f"refresh_ahead must be a bool, got {refresh_ahead!r}")
        self.ttl_s = float(ttl_s)
        self.max_entries = int(max_entries)
        self.refresh_ahead = refresh_ahead
        self._clock = clock if clock is not None else _monotonic
        self._entries: dict[str, _Entry] = {}
        self._lock = threading.Lock()
        #: Grows with every :meth:`clear`; :meth:`put` drops a sign-in read before it.
        self.generation = 0
        self._inflight: dict[str, _Flight] = {}
        self._background = BackgroundTasks(MAX_REFRESHING)
        self._failing = False  # the last background lookup failed (logged once)
        #: Tokens whose background lookup failed, with the entry it was for: that entry is
        #: left to expire, not looked up again on every later hit.
        self._not_again: dict[str, _Entry] = {}
        #: Database lookups made by :meth:`sign_in` (requests and background), requests
        #: that shared one in flight, background lookups started and failed.
        self.lookups = 0
        self.shared = 0
        self.refreshes = 0
        self.refresh_failures = 0
        #: Where every successful sign-in is also noted for the emergency stop (None: not).
        self.known: KnownTokens | None = None
        _caches.add(self)

    def _fresh(self, token_hash: str, refresh: Lookup | None = None) -> _Entry | None:
        """The entry of ``token_hash`` if still valid: within the TTL and before the
        token's expiry, checked on every hit (an entry past either is dropped).  A hit in
        the last part of the TTL starts the background lookup ``refresh``, if given."""
        now = self._clock()
        with self._lock:
            e = self._entries.get(token_hash)
            if e is None:
                return None
            if now >= e.until or (e.expires_at is not None and e.expires_at <= utcnow()):
                del self._entries[token_hash]
                return None
        if (
            refresh is not None and now >= e.until - REFRESH_AHEAD_FRACTION * self.ttl_s
            and self._not_again.get(token_hash) is not e
        ):  # fmt: skip
            self._refresh(token_hash, refresh)
        return e

    def get(self, token_hash: str, *, refresh: Lookup | None = None) -> User | None:
        """A fresh, detached copy of the cached user of ``token_hash`` (None: ask the
        database); ``refresh``: the token's lookup, run in the background when the entry
        is due (module doc)."""
        e = self._fresh(token_hash, refresh)
        return None if e is None else _user(e.user)

    def role_of(self, token_hash: str, *, refresh: Lookup | None = None) -> str | None:
        """The role name of the cached user of ``token_hash``, under the same checks as
        :meth:`get` (None: ask the database), without building a :class:`User`."""
        e = self._fresh(token_hash, refresh)
        return None if e is None else e.user[2]

    async def sign_in(self, token_hash: str, lookup: Lookup) -> User | None:
        """The user ``token_hash`` signs in: from a fresh entry (refreshed ahead when
        due), else from the lookup of the token in flight if one started since the last
        change (:attr:`generation`), else from ``lookup()``, remembered when it succeeds.
        None: refused (never remembered)."""
        user = self.get(token_hash, refresh=lookup)
        if user is not None:
            return user
        if not self.refresh_ahead or self.ttl_s <= 0:
            generation, started = self.generation, self._clock()
            self.lookups += 1
            found = await lookup()
            if found is None:
                return None
            self.put(token_hash, found[0], found[1], generation=generation, started=started)
            return found[0]
        loop = asyncio.get_running_loop()
        flight = self._inflight.get(token_hash)
        if flight is not None and flight.loop is loop and flight.generation == self.generation:
            self.shared += 1
            try:
                got = await asyncio.shield(flight.future)
            except asyncio.CancelledError:
                task = asyncio.current_task()
                if not flight.future.cancelled() or (task is not None and task.cancelling()):
                    raise  # this request was cancelled, not the lookup it waited for
                return await self.sign_in(token_hash, lookup)  # its owner went away
            if got is None:
                return None
            row, expires_at = got
            if expires_at is not None and expires_at <= utcnow():
                return None
            return _user(row)
        mine = self._start(token_hash, loop)
        started = self._clock()
        try:
            found = await work_for_waiters(mine.future, lookup())
        finally:
            if self._inflight.get(token_hash) is mine:
                del self._inflight[token_hash]
        if found is None:
            mine.future.set_result(None)
            return None
        mine.future.set_result((_row(found[0]), _aware(found[1])))
        self.put(token_hash, found[0], found[1], generation=mine.generation, started=started)
        return found[0]

    def _start(self, token_hash: str, loop: asyncio.AbstractEventLoop) -> _Flight:
        """Register a lookup of ``token_hash`` in flight, from now's generation."""
        flight = _Flight(loop, self.generation, loop.create_future())
        self._inflight[token_hash] = flight
        self.lookups += 1
        return flight

    def _refresh(self, token_hash: str, lookup: Lookup) -> None:
        """Start the background lookup of ``token_hash`` unless off, one is in flight for
        it, :data:`MAX_REFRESHING` run, or this is not called from a coroutine."""
        if (
            not self.refresh_ahead or self._background.closed or self.ttl_s <= 0
            or token_hash in self._inflight or self._background.full()
        ):  # fmt: skip
            return
        try:
            loop = asyncio.get_running_loop()
        except RuntimeError:
            return
        flight = self._start(token_hash, loop)
        self._background.spawn(
            loop, self._refresh_run(token_hash, lookup, flight), name="sign-in refresh"
        )
        self.refreshes += 1

    async def _refresh_run(self, token_hash: str, lookup: Lookup, flight: _Flight) -> None:
        """The background lookup: the entry replaced (the token still valid) or dropped
        (refused now); shared with requests that miss meanwhile; never raises but its
        cancellation."""
        with self._lock:
            old = self._entries.get(token_hash)
        started = self._clock()
        try:
            found = await lookup()
        except asyncio.CancelledError:
            flight.future.cancel()  # its waiters look up themselves
            raise
        except BaseException as exc:
            flight.future.set_exception(exc)
            flight.future.exception()
            if not isinstance(exc, Exception):
                raise
            self.refresh_failures += 1
            if old is not None:
                with self._lock:
                    self._not_again[token_hash] = old
                    while len(self._not_again) > MAX_REFRESHING * 4:  # bounded: oldest go
                        del self._not_again[next(iter(self._not_again))]
            if not self._failing:
                self._failing = True
                log.warning(
                    "sign-in cache: background lookup failed (logged once until one "
                    "succeeds; the entry expires as usual): %r", exc,
                )  # fmt: skip
            return
        finally:
            if self._inflight.get(token_hash) is flight:
                del self._inflight[token_hash]
        if self._failing:
            self._failing = False
            log.info("sign-in cache: background lookups succeed again")
        with self._lock:
            self._not_again.pop(token_hash, None)
        if found is None:  # revoked, expired or disabled since: refused from now on
            flight.future.set_result(None)
            with self._lock:
                self._entries.pop(token_hash, None)
            return
        flight.future.set_result((_row(found[0]), _aware(found[1])))
        self.put(token_hash, found[0], found[1], generation=flight.generation, started=started)

    @property
    def refreshing(self) -> int:
        """Background lookups in flight."""
        return len(self._background)

    def open(self) -> None:
        """Let background lookups start again after :meth:`close`."""
        self._background.open()

    async def close(self) -> None:
        """Cancel the background lookups and wait for their end (those of this event
        loop; another loop's are only cancelled), start none until :meth:`open`, and
        forget every entry."""
        await self._background.close()
        self.clear()

    def put(
        self, token_hash: str, user: User, expires_at: datetime | None, *, generation: int,
        started: float | None = None,
    ) -> None:  # fmt: skip
        """Remember a successful sign-in read from the database when :attr:`generation`
        was ``generation`` (a user or token change committed since: not remembered), its
        lookup started at ``started`` (the cache's clock; default now): the entry
        lasts :attr:`ttl_s` from then."""
        if user.disabled:
            return
        if self.known is not None and generation == self.generation:
            self.known.note(token_hash, user_id=int(user.id), user=user.name, role=user.role)
        if self.ttl_s <= 0:
            return
        at = self._clock() if started is None else started
        entry = _Entry(at + self.ttl_s, _aware(expires_at), _row(user))
        with self._lock:
            if generation != self.generation:
                return
            old = self._entries.get(token_hash)
            if old is not None and old.until > entry.until:
                return  # a later lookup's entry is kept already
            self._entries.pop(token_hash, None)
            self._entries[token_hash] = entry
            while len(self._entries) > self.max_entries:
                del self._entries[next(iter(self._entries))]

    def forget_users(self, user_ids: frozenset[int] | None) -> int:
        """Drop the entries of ``user_ids`` (None: every entry); returns how many.  A
        sign-in read from the database before this call is not remembered after it;
        :attr:`known` forgets them too."""
        if self.known is not None:
            self.known.forget_users(user_ids)
        with self._lock:
            self.generation += 1
            if user_ids is None:
                n = len(self._entries)
                self._entries.clear()
                return n
            gone = [k for k, e in self._entries.items() if e.user[0] in user_ids]
            for k in gone:
                del self._entries[k]
            return len(gone)

    def clear(self) -> None:
        """Forget every entry."""
        with self._lock:
            self._entries.clear()
            self.generation += 1

    def __len__(self) -> int:
        with self._lock:
            return len(self._entries)


def clear_all() -> None:
    """Clear every cache of this process (a user or token changed)."""
    for cache in list(_caches):
        cache.clear()


#: Changes that do not change who may sign in (a sign-in's own bookkeeping).
_HARMLESS = frozenset({"last_used_at"})


def _changed(obj: Any) -> set[str]:
    return {a.key for a in sa_inspect(obj).attrs if a.history.has_changes()}


def _user_id(o: User | ApiToken) -> int | None:
    uid = o.id if isinstance(o, User) else o.user_id
    return None if uid is None else int(uid)


def _touch(session: Session, ids: set[int] | None) -> None:
    """Record that this transaction changed the sign-ins of ``ids`` (None: any user)."""
    known = session.info.get(_USERS, set())
    session.info[_USERS] = None if ids is None or known is None else known | ids


@event.listens_for(Session, "after_flush")
def _after_flush(session: Session, _ctx: Any) -> None:
    if any(isinstance(o, User | ApiToken) for o in session.new):
        session.info[_FLAG] = True  # a new user or token: nobody has it cached elsewhere
    changed = [o for o in session.deleted if isinstance(o, User | ApiToken)]
    changed += [
        o for o in session.dirty if isinstance(o, User | ApiToken) and not _changed(o) <= _HARMLESS
    ]
    if changed:
        session.info[_FLAG] = True
        ids = {_user_id(o) for o in changed}
        _touch(session, None if None in ids else {i for i in ids if i is not None})


@event.listens_for(Session, "do_orm_execute")
def _do_orm_execute(state: ORMExecuteState) -> None:
    if state.is_insert or state.is_update or state.is_delete:
        table = getattr(state.statement, "table", None)
        if getattr(table, "name", None) in _WATCHED:
            state.session.info[_FLAG] = True
            if not state.is_insert:
                ids = state.execution_options.get(AUTH_USERS_OPTION)
                _touch(state.session, None if ids is None else {int(i) for i in ids})


def notify_payload(ids: set[int] | None) -> str:
    """What a sign-in notification carries: ``pid=P;users=1,2`` (``*``: any user)."""
    import os

    listed = "*" if ids is None or len(ids) > _MAX_IDS else ",".join(map(str, sorted(ids)))
    return f"pid={os.getpid()};users={listed}"


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


@event.listens_for(Session, "before_commit")
def _before_commit(session: Session) -> None:
    if session.new or session.dirty or session.deleted:
        session.flush()  # the commit's own flush comes after this hook: do it now
    if _USERS not in session.info:
        return
    ids = session.info.pop(_USERS)
    session.info[_FORGET] = ids  # for the known tokens, once the commit succeeded
    bind = session.get_bind()
    if bind.dialect.name == "postgresql":
        # delivered to the plant's listeners when (and only if) this transaction commits
        session.connection().execute(
            text("SELECT pg_notify(:channel, :payload)"),
            {"channel": AUTH_CHANNEL, "payload": notify_payload(ids)},
        )


@event.listens_for(Session, "after_commit")
def _after_commit(session: Session) -> None:
    if session.info.pop(_FLAG, False):
        clear_all()
    if _FORGET in session.info:
        ids = session.info.pop(_FORGET)
        for cache in list(_caches):
            if cache.known is not None:
                cache.known.forget_users(ids)


@event.listens_for(Session, "after_rollback")
def _after_rollback(session: Session) -> None:
    session.info.pop(_FLAG, None)
    session.info.pop(_USERS, None)
    session.info.pop(_FORGET, None)
