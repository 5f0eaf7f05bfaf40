"""API tokens: creation, hashing and lookup.

A token is ``vc_`` followed by 32 random bytes (URL-safe base64).  Only its HMAC-SHA256
under the configured secret is stored, so a copy of the database does not reveal usable
tokens.  Roles are ordered ``viewer < operator < engineer``.
"""

from __future__ import annotations

import hashlib
import hmac
import re
import secrets
from datetime import datetime, timedelta
from typing import Any

from sqlalchemy import or_, select, update
from sqlalchemy.exc import IntegrityError
from sqlalchemy.ext.asyncio import AsyncSession
from sqlalchemy.orm import selectinload

from backend.caches import users_changed
from backend.db.models import ApiToken, Role, User
from backend.db.types import utcnow
from backend.knowntokens import KnownTokens
from vision.errors import Conflict, InvalidInput

__all__ = [
    "LAST_USED_RESOLUTION_S",
    "MAX_EXPIRES_IN_DAYS",
    "TOKEN_PREFIX",
    "UserExists",
    "authenticate",
    "authenticate_with_expiry",
    "create_user",
    "hash_token",
    "issue_token",
    "live_token_clause",
    "load_known_tokens",
    "parse_role",
    "revoke_tokens",
    "token_expiry",
    "token_is_live",
    "validate_user_name",
    "well_formed",
]

TOKEN_PREFIX = "vc_"
#: Longest lifetime a token may be given, days (ten years).
MAX_EXPIRES_IN_DAYS = 3650


class UserExists(Conflict, ValueError):
    """A user of that name exists already (a ``ValueError`` too, for the command line)."""


_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.@-]{0,63}$")


def parse_role(value: str) -> Role:
    """The :class:`Role` named ``value``; :class:`InvalidInput` (a ``ValueError``) listing
    the roles otherwise."""
    try:
        return Role[value]
    except KeyError:
        raise InvalidInput(
            f"role must be one of {', '.join(r.name for r in Role)}, got {value!r}"
        ) from None


def validate_user_name(name: str) -> str:
    """Return ``name`` if it is a valid user name, else raise :class:`InvalidInput` (a
    ``ValueError``) quoting it."""
    if not _NAME.match(name):
        raise InvalidInput(
            f"user name must be 1-64 characters of letters, digits, '_', '.', '@', '-' "
            f"starting with a letter or digit, got {name!r}"
        )
    return name


def hash_token(token: str, secret: str) -> str:
    """HMAC-SHA256 of the token under the secret, hex."""
    return hmac.new(secret.encode(), token.encode(), hashlib.sha256).hexdigest()


def token_expiry(expires_in_days: float | None, *, now: datetime | None = None) -> datetime | None:
    """The expiry instant of a token valid for ``expires_in_days`` days (None: never).

    :class:`InvalidInput` unless ``0 < expires_in_days <= MAX_EXPIRES_IN_DAYS``.
    """
    if expires_in_days is None:
        return None
    if (
        isinstance(expires_in_days, bool)
        or not isinstance(expires_in_days, int | float)
        or not 0 < expires_in_days <= MAX_EXPIRES_IN_DAYS
    ):
        raise InvalidInput(
            f"expires_in_days must be a number of days in (0, {MAX_EXPIRES_IN_DAYS}], "
            f"got {expires_in_days!r}"
        )
    return (now or utcnow()) + timedelta(days=float(expires_in_days))


async def issue_token(
    session: AsyncSession,
    user: User,
    secret: str,
    *,
    label: str = "",
    expires_at: datetime | None = None,
) -> str:
    """Create a new token for ``user`` (valid until ``expires_at``, None: no expiry) and
    return it (it is not stored in clear)."""
    token = TOKEN_PREFIX + secrets.token_urlsafe(32)
    session.add(
        ApiToken(
            user_id=user.id,
            token_hash=hash_token(token, secret),
            prefix=token[:10],
            label=label[:64],
            expires_at=expires_at,
        )
    )
    await session.flush()
    return token


def live_token_clause(now: datetime | None = None) -> Any:
    """SQL condition: the token row is neither revoked nor expired at ``now``."""
    return ApiToken.revoked.is_(False) & or_(
        ApiToken.expires_at.is_(None), ApiToken.expires_at > (now or utcnow())
    )


async def create_user(
    session: AsyncSession,
    name: str,
    role: Role,
    secret: str,
    *,
    label: str = "created",
    expires_at: datetime | None = None,
) -> tuple[User, str]:
    """Create a user with one token; :class:`InvalidInput` if the name is invalid,
    :class:`UserExists` (a :class:`Conflict`) if it is taken; both are ``ValueError`` too."""
    validate_user_name(name)
    existing = await session.scalar(select(User).where(User.name == name))
    if existing is not None:
        raise UserExists(f"user {name!r} already exists")
    user = User(name=name, role=role.name)
    try:
        # Another request may create the same name between the check above and this insert;
        # the unique index then refuses it, and that is a 409, not a 500. The session must
        # then be rolled back as a whole (the caller's unit of work fails with the conflict).
        # No savepoint here: pysqlite opens no transaction for a SELECT, so a SAVEPOINT
        # becomes the outermost transaction and its RELEASE commits the row on its own,
        # even when the caller later rolls back (a user created without its audit row).
        session.add(user)
        await session.flush()
    except IntegrityError:
        raise UserExists(f"user {name!r} already exists") from None
    return user, await issue_token(session, user, secret, label=label, expires_at=expires_at)


async def revoke_tokens(session: AsyncSession, user: User, *, label: str | None = None) -> int:
    """Revoke the user's tokens (only those with ``label`` if given); returns how many.
    The sign-in caches of the plant forget the user (:func:`backend.caches.users_changed`)."""
    stmt = update(ApiToken).where(ApiToken.user_id == user.id, ApiToken.revoked.is_(False))
    if label is not None:
        stmt = stmt.where(ApiToken.label == label)
    result = await session.execute(stmt.values(revoked=True))
    if result.rowcount:  # type: ignore[attr-defined]
        await users_changed(session, {int(user.id)})
    return int(result.rowcount or 0)  # type: ignore[attr-defined]


#: How stale a token's ``last_used_at`` may get before a request writes it again, seconds.
LAST_USED_RESOLUTION_S = 60.0


def well_formed(token: object) -> bool:
    """Whether ``token`` has the shape of a VisionCell token (checked before any lookup)."""
    return isinstance(token, str) and token.startswith(TOKEN_PREFIX) and len(token) <= 200


async def authenticate(session: AsyncSession, token: str, secret: str) -> User | None:
    """The enabled user owning ``token`` if it is neither revoked nor expired, or None."""
    found = await authenticate_with_expiry(session, token, secret)
    return None if found is None else found[0]


async def authenticate_with_expiry(
    session: AsyncSession, token: str, secret: str
) -> tuple[User, datetime | None] | None:
    """:func:`authenticate` with the token's expiry (for :class:`backend.caches.AuthCache`)."""
    if not well_formed(token):
        return None
    row = await session.scalar(
        select(ApiToken)
        .options(selectinload(ApiToken.user))
        .where(ApiToken.token_hash == hash_token(token, secret), live_token_clause())
    )
    if row is None or row.user.disabled:
        return None
    now = utcnow()
    last = row.last_used_at
    if last is not None and last.tzinfo is None:
        last = last.replace(tzinfo=now.tzinfo)
    # A write per request made every read a write transaction (on SQLite, one writer at a
    # time: readers queued behind inspections); "last used" to the minute is enough.
    if last is None or (now - last).total_seconds() >= LAST_USED_RESOLUTION_S:
        row.last_used_at = now
    return row.user, row.expires_at


async def token_is_live(session: AsyncSession, token: str, secret: str) -> bool:
    """True while ``token`` still signs its user in (no write, for periodic re-checks)."""
    if not isinstance(token, str) or not token.startswith(TOKEN_PREFIX) or len(token) > 200:
        return False
    row = await session.scalar(
        select(ApiToken)
        .options(selectinload(ApiToken.user))
        .where(ApiToken.token_hash == hash_token(token, secret), live_token_clause())
    )
    return row is not None and not row.user.disabled


async def load_known_tokens(session: AsyncSession, known: KnownTokens) -> int:
    """Note every live token of an enabled user in ``known`` (the most recently used
    first, at most ``known.max_entries``), so that the emergency stop accepts a valid
    token from memory from the start; returns how many were noted."""
    rows = await session.execute(
        select(ApiToken.token_hash, User.id, User.name, User.role)
        .join(User, ApiToken.user_id == User.id)
        .where(live_token_clause(), User.disabled.is_(False))
        .order_by(ApiToken.last_used_at.desc().nulls_last(), ApiToken.id.desc())
        .limit(known.max_entries)
    )
    n = 0
    for token_hash, user_id, name, role in reversed(rows.all()):  # the newest noted last
        known.note(str(token_hash), user_id=int(user_id), user=str(name), role=str(role))
        n += 1
    return n
