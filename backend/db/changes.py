"""Tell the other processes of a plant that the object models or trained views changed.

Several cells (``visioncell serve`` processes) share one PostgreSQL database and its models;
each keeps an in-memory index of the trained views (:mod:`backend.recognition.index`), which
must learn of a model taught, renamed or deleted by another process without a restart.

Every session of a PostgreSQL :class:`~backend.db.session.Database` is a
:class:`NotifyingSession`: when a transaction inserted, changed or deleted a row of
:data:`WATCHED` (ORM objects or bulk ``insert``/``update``/``delete`` statements), it sends
``pg_notify(CHANNEL, payload)`` inside that transaction just before the commit.  PostgreSQL
delivers a notification only when its transaction commits, so listeners hear of committed
changes only, never of a rolled-back one (PostgreSQL documentation, "NOTIFY").  The listener
side is :class:`backend.recognition.sync.IndexSync`; SQLite has no notifications, and there
the index polls a cheap change counter instead (:func:`backend.recognition.sync.fingerprint`).
"""

from __future__ import annotations

import itertools
import os
from typing import Any

from sqlalchemy import event, text
from sqlalchemy.orm import ORMExecuteState, Session

__all__ = ["CHANNEL", "WATCHED", "NotifyingSession", "payload"]

#: The notification channel (a PostgreSQL identifier).
CHANNEL = "visioncell_index"
#: Tables whose changes the live indexes of the plant must learn of.
WATCHED = frozenset({"object_models", "trained_views"})
_FLAG = "visioncell_watched_change"


def payload() -> str:
    """What a notification carries: the sending process id (a listener may ignore its own)."""
    return f"pid={os.getpid()}"


class NotifyingSession(Session):
    """A session that notifies :data:`CHANNEL` when it commits a change of :data:`WATCHED`."""


def _touches_watched(objects: Any) -> bool:
    return any(getattr(o, "__tablename__", None) in WATCHED for o in objects)


@event.listens_for(NotifyingSession, "after_flush")
def _after_flush(session: Session, _ctx: Any) -> None:
    if _touches_watched(itertools.chain(session.new, session.dirty, session.deleted)):
        session.info[_FLAG] = True


@event.listens_for(NotifyingSession, "do_orm_execute")
def _do_orm_execute(state: ORMExecuteState) -> None:
    if state.is_insert or state.is_update or state.is_delete:
        table = getattr(state.statement, "table", None)
        if getattr(table, "name", None) in WATCHED:
            state.session.info[_FLAG] = True


@event.listens_for(NotifyingSession, "before_commit")
def _before_commit(session: Session) -> None:
    if session.new or session.dirty or session.deleted:
        session.flush()  # the commit's own flush comes after this hook: do it now
    if session.info.pop(_FLAG, False):
        session.connection().execute(
            text("SELECT pg_notify(:channel, :payload)"),
            {"channel": CHANNEL, "payload": payload()},
        )


@event.listens_for(NotifyingSession, "after_rollback")
def _after_rollback(session: Session) -> None:
    session.info.pop(_FLAG, None)
