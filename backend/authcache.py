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
"""

from __future__ import annotations

import threading
import time
import weakref
from dataclasses import dataclass
from datetime import datetime
from typing import Any

from sqlalchemy import event, text
from sqlalchemy import inspect as sa_inspect
from sqlalchemy.orm import ORMExecuteState, Session

from backend.db.models import ApiToken, User
from backend.db.types import utcnow

__all__ = [
    "AUTH_CHANNEL",
    "AUTH_USERS_OPTION",
    "MAX_ENTRIES",
    "TTL_S",
    "AuthCache",
    "parse_payload",
]

#: How long a successful sign-in is reused, seconds.
TTL_S = 2.0
#: Most tokens kept (the oldest entries go first beyond it).
MAX_ENTRIES = 10_000
_WATCHED = frozenset({"users", "api_tokens"})
_FLAG = "visioncell_auth_change"
#: Users whose sign-ins a transaction changed (a set of ids, or None: any user).
_USERS = "visioncell_auth_users"
#: The notification channel of sign-in changes (a PostgreSQL identifier).
AUTH_CHANNEL = "visioncell_auth"
#: Execution option of a bulk ``update``/``delete`` of users or tokens naming the user ids
#: it touches (``backend.auth.revoke_tokens``); without it a notification says "any user".
AUTH_USERS_OPTION = "visioncell_auth_users"
#: Most user ids one notification lists (PostgreSQL caps a payload at 8000 bytes).
_MAX_IDS = 500
_caches: weakref.WeakSet[AuthCache] = weakref.WeakSet()


@dataclass(frozen=True)
class _Entry:
    until: float
    expires_at: datetime | None
    user: tuple[int, str, str, bool, datetime]


class AuthCache:
    """Successful sign-ins by token hash for ``ttl_s`` seconds (see the module doc)."""

    def __init__(self, *, ttl_s: float = TTL_S, max_entries: int = MAX_ENTRIES) -> None:
        if not 0.0 <= float(ttl_s) <= 60.0:
            raise ValueError(f"ttl_s must be within 0..60 s, got {ttl_s!r}")
        if not 1 <= int(max_entries) <= 1_000_000:
            raise ValueError(f"max_entries must be within 1..1e6, got {max_entries!r}")
        self.ttl_s = float(ttl_s)
        self.max_entries = int(max_entries)
        self._entries: dict[str, _Entry] = {}
        self._lock = threading.Lock()
        #: Grows with every :meth:`clear`; :meth:`put` drops a sign-in read before it.
        self.generation = 0
        _caches.add(self)

    def _fresh(self, token_hash: str) -> _Entry | None:
        """The entry of ``token_hash`` if still valid: within the TTL and before the
        token's expiry, checked on every hit (an entry past either is dropped)."""
        with self._lock:
            e = self._entries.get(token_hash)
            if e is None:
                return None
            if time.monotonic() >= e.until or (
                e.expires_at is not None and e.expires_at <= utcnow()
            ):
                del self._entries[token_hash]
                return None
            return e

    def get(self, token_hash: str) -> User | None:
        """A fresh, detached copy of the cached user of ``token_hash`` (None: ask the
        database)."""
        e = self._fresh(token_hash)
        if e is None:
            return None
        uid, name, role, disabled, created = e.user
        return User(id=uid, name=name, role=role, disabled=disabled, created_at=created)

    def role_of(self, token_hash: str) -> str | None:
        """The role name of the cached user of ``token_hash``, under the same checks as
        :meth:`get` (None: ask the database), without building a :class:`User`."""
        e = self._fresh(token_hash)
        return None if e is None else e.user[2]

    def put(
        self, token_hash: str, user: User, expires_at: datetime | None, *, generation: int
    ) -> None:
        """Remember a successful sign-in read from the database when :attr:`generation`
        was ``generation`` (a user or token change committed since: not remembered)."""
        if self.ttl_s <= 0 or user.disabled:
            return
        if expires_at is not None and expires_at.tzinfo is None:
            expires_at = expires_at.replace(tzinfo=utcnow().tzinfo)
        entry = _Entry(
            time.monotonic() + self.ttl_s,
            expires_at,
            (int(user.id), str(user.name), str(user.role), bool(user.disabled), user.created_at),
        )
        with self._lock:
            if generation != self.generation:
                return
            self._entries.pop(token_hash, None)
            self._entries[token_hash] = entry
            while len(self._entries) > self.max_entries:
                del self._entries[next(iter(self._entries))]

    def forget_users(self, user_ids: frozenset[int] | None) -> int:
        """Drop the entries of ``user_ids`` (None: every entry); returns how many.  A
        sign-in read from the database before this call is not remembered after it."""
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


@event.listens_for(Session, "after_rollback")
def _after_rollback(session: Session) -> None:
    session.info.pop(_FLAG, None)
    session.info.pop(_USERS, None)
