"""The audit trail: every change of a threshold, object model, trained view, active
calibration, recipe (and which one is active), user or token, with who, when, what, old and new value and why.

:func:`record` adds the row to the session of the change itself, so the change and its row
commit together or not at all (no change without its row, no row for a refused change).
Values are stored as JSON with secrets removed (:data:`SECRET_KEYS` are dropped at any
depth: never a token or its hash).  :func:`query` reads the trail for ``GET /api/audit``;
nothing edits or deletes rows.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from datetime import datetime
from typing import Any

from sqlalchemy import func, select
from sqlalchemy.ext.asyncio import AsyncSession

from backend.db.models import AuditEntry, User
from backend.db.types import utcnow
from vision.errors import InvalidInput

__all__ = [
    "CLI",
    "KINDS",
    "MAX_REASON_LENGTH",
    "MAX_VALUE_BYTES",
    "SECRET_KEYS",
    "SYSTEM",
    "Actor",
    "By",
    "query",
    "record",
]

#: What can be changed, and so recorded (``estop``: a press or reset of the emergency stop,
#: recorded after the stop itself by :class:`backend.estoplog.EStopLog`).
KINDS = ("threshold", "model", "view", "negative", "calibration", "user", "token", "estop",
         "recipe")  # fmt: skip
#: Longest reason a changing endpoint accepts (characters).
MAX_REASON_LENGTH = 500
#: Largest old or new value stored, bytes of JSON; a larger one is stored as a summary.
MAX_VALUE_BYTES = 64_000
#: Keys never stored, at any depth of a value.
SECRET_KEYS = frozenset({"token", "token_hash", "prefix", "secret", "secret_key", "password"})
_MAX_ENTITY = 64
_MAX_ACTION = 32


@dataclass(frozen=True)
class Actor:
    """Who made a change: a user (name and role), or ``cli`` / ``system``."""

    name: str
    role: str

    @classmethod
    def of(cls, user: User) -> Actor:
        """The actor for an API user."""
        return cls(user.name, user.role)


#: Changes made by the ``visioncell`` command line.
CLI = Actor("cli", "cli")
#: Automatic changes (the automatic threshold, start-up tokens, activation by a job).
SYSTEM = Actor("system", "system")


@dataclass(frozen=True)
class By:
    """Who asks for a change and why, handed from the edge to the service that records it."""

    actor: Actor = SYSTEM
    reason: str | None = None


def _clean(value: Any) -> Any:
    """``value`` as JSON-able data without secrets (non-finite floats become None)."""
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items() if str(k) not in SECRET_KEYS}
    if isinstance(value, list | tuple | set | frozenset):
        return [_clean(v) for v in value]
    if isinstance(value, bool) or value is None or isinstance(value, int | str):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, datetime):
        return value.isoformat()
    if hasattr(value, "value") and isinstance(value.value, str):  # enums
        return value.value
    if hasattr(value, "tolist"):  # numpy
        return _clean(value.tolist())
    return str(value)


def _value(value: dict[str, Any] | None) -> dict[str, Any] | None:
    if value is None:
        return None
    if not isinstance(value, dict):
        raise InvalidInput(f"audit values are objects or None, got {type(value).__name__}")
    clean = _clean(value)
    size = len(json.dumps(clean))
    if size > MAX_VALUE_BYTES:
        return {"truncated": True, "bytes": size, "keys": sorted(clean)[:50]}
    return clean


def check_reason(reason: str | None) -> str:
    """The reason as stored ("" for none); :class:`InvalidInput` if it is too long."""
    if reason is None:
        return ""
    if not isinstance(reason, str):
        raise InvalidInput(f"reason must be text, got {reason!r}")
    if len(reason) > MAX_REASON_LENGTH:
        raise InvalidInput(
            f"reason must be at most {MAX_REASON_LENGTH} characters, got {len(reason)}"
        )
    return reason.strip()


def record(
    session: AsyncSession,
    *,
    actor: Actor,
    kind: str,
    entity_id: int | str,
    action: str,
    old: dict[str, Any] | None,
    new: dict[str, Any] | None,
    reason: str | None,
) -> AuditEntry:
    """Add one audit row to ``session`` (it commits with the change).

    Parameters
    ----------
    session
        The session of the change itself.
    actor
        Who changed it (:meth:`Actor.of` a user, :data:`CLI` or :data:`SYSTEM`).
    kind
        One of :data:`KINDS`.
    entity_id
        The changed row's id (``"global"`` for the global threshold).
    action
        What was done: ``create``, ``update``, ``delete``, ``add``, ``set``, ``auto``, ...
    old, new
        The value before and after (None when there was none); secrets are dropped.
    reason
        Why, at most :data:`MAX_REASON_LENGTH` characters (None: not given).
    """
    if kind not in KINDS:
        raise InvalidInput(f"audit kind must be one of {', '.join(KINDS)}, got {kind!r}")
    entity = str(entity_id)
    if not 1 <= len(entity) <= _MAX_ENTITY:
        raise InvalidInput(f"audit entity id must be 1..{_MAX_ENTITY} characters, got {entity!r}")
    if not isinstance(action, str) or not 1 <= len(action) <= _MAX_ACTION:
        raise InvalidInput(f"audit action must be 1..{_MAX_ACTION} characters, got {action!r}")
    if not isinstance(actor, Actor) or not actor.name:
        raise InvalidInput(f"audit actor must be an Actor with a name, got {actor!r}")
    row = AuditEntry(
        at=utcnow(),
        actor=actor.name[:64],
        actor_role=actor.role[:16],
        kind=kind,
        entity_id=entity,
        action=action,
        old=_value(old),
        new=_value(new),
        reason=check_reason(reason),
    )
    session.add(row)
    return row


async def query(
    session: AsyncSession,
    *,
    kind: str | None = None,
    entity_id: str | None = None,
    actor: str | None = None,
    since: datetime | None = None,
    until: datetime | None = None,
    limit: int = 100,
    offset: int = 0,
) -> tuple[list[AuditEntry], int]:
    """A page of the trail, newest first, and the number of rows matching the filters.

    ``since`` is inclusive and ``until`` exclusive; both must be timezone-aware.
    """
    if not 1 <= limit <= 500 or offset < 0:
        raise InvalidInput(f"limit must be in 1..500 and offset >= 0, got {limit}, {offset}")
    if kind is not None and kind not in KINDS:
        raise InvalidInput(f"kind must be one of {', '.join(KINDS)}, got {kind!r}")
    for what, t in (("since", since), ("until", until)):
        if t is not None and t.tzinfo is None:
            raise InvalidInput(f"{what} must carry a time zone (e.g. ...Z), got {t.isoformat()}")
    if since is not None and until is not None and until < since:
        raise InvalidInput(f"until ({until.isoformat()}) is before since ({since.isoformat()})")
    where = []
    if kind is not None:
        where.append(AuditEntry.kind == kind)
    if entity_id is not None:
        where.append(AuditEntry.entity_id == entity_id)
    if actor is not None:
        where.append(AuditEntry.actor == actor)
    if since is not None:
        where.append(AuditEntry.at >= since)
    if until is not None:
        where.append(AuditEntry.at < until)
    total = await session.scalar(select(func.count()).select_from(AuditEntry).where(*where))
    rows = await session.scalars(
        select(AuditEntry).where(*where).order_by(AuditEntry.id.desc()).limit(limit).offset(offset)
    )
    return list(rows), int(total or 0)
