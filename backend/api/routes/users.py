"""Users and tokens (engineer role)."""

from __future__ import annotations

from datetime import datetime
from typing import Annotated, Any, Literal

from fastapi import APIRouter, Query, status
from pydantic import BaseModel, Field
from sqlalchemy import func, select

from backend import audit
from backend.api.deps import EngineerUser, SessionDep, SettingsDep, ViewerUser
from backend.api.schemas import Page
from backend.api.types import DbId, Limit, NameStr, Offset
from backend.auth import (
    MAX_EXPIRES_IN_DAYS,
    create_user,
    hash_token,
    issue_token,
    parse_role,
    token_expiry,
)
from backend.caches import users_changed
from backend.db.models import ApiToken, User
from backend.db.types import utcnow
from vision.errors import Conflict, NotFound

router = APIRouter(prefix="/users", tags=["users"])


class UserCreate(BaseModel):
    name: str = Field(
        min_length=1,
        max_length=64,
        description="Letters, digits, '_', '.', '@', '-', starting with a letter or digit",
    )
    role: Literal["viewer", "operator", "engineer"] = Field(
        description="viewer, operator or engineer"
    )
    expires_in_days: float | None = Field(
        None,
        gt=0,
        le=MAX_EXPIRES_IN_DAYS,
        allow_inf_nan=False,
        strict=True,
        description="Lifetime of the first token, days (omitted: no expiry)",
    )

    reason: str | None = Field(
        None, max_length=audit.MAX_REASON_LENGTH, description="Why (audit trail)"
    )


class UserRoleIn(BaseModel):
    role: Literal["viewer", "operator", "engineer"] = Field(
        description="viewer, operator or engineer"
    )
    reason: str | None = Field(
        None, max_length=audit.MAX_REASON_LENGTH, description="Why (audit trail)"
    )


class TokenCreate(BaseModel):
    label: str = Field("", max_length=64, pattern=r"^[A-Za-z0-9 _.@-]*$", description="A note")
    expires_in_days: float | None = Field(
        None,
        gt=0,
        le=MAX_EXPIRES_IN_DAYS,
        allow_inf_nan=False,
        strict=True,
        description="Lifetime of the token, days (omitted: no expiry)",
    )


class TokenPublic(BaseModel):
    """A token as listed: never its secret, only the first characters."""

    id: int
    prefix: str
    label: str
    created_at: datetime
    last_used_at: datetime | None
    expires_at: datetime | None
    revoked: bool
    expired: bool

    @classmethod
    def of(cls, row: ApiToken) -> TokenPublic:
        """The listing of a token row (``expired``: as of now)."""
        expired = row.expires_at is not None and row.expires_at <= utcnow()
        return cls(
            id=row.id,
            prefix=row.prefix,
            label=row.label,
            created_at=row.created_at,
            last_used_at=row.last_used_at,
            expires_at=row.expires_at,
            revoked=row.revoked,
            expired=expired,
        )


class TokenCreated(BaseModel):
    token: str = Field(description="The new token, shown once")
    info: TokenPublic


class UserPublic(BaseModel):
    id: int
    name: str
    role: str
    created_at: datetime
    disabled: bool


class MeOut(BaseModel):
    name: str
    role: str


class UserCreated(BaseModel):
    user: UserPublic
    token: str = Field(description="The new token, shown once")


class UserDisabled(BaseModel):
    name: str
    disabled: bool
    tokens_revoked: int


@router.get("/me", summary="The user owning the token", response_model=MeOut)
async def read_me(user: ViewerUser) -> dict[str, Any]:
    return {"name": user.name, "role": user.role}


@router.get("", summary="All users", response_model=Page[UserPublic])
async def read_users(
    _: EngineerUser, session: SessionDep, limit: Limit = 100, offset: Offset = 0
) -> dict[str, Any]:
    total = await session.scalar(select(func.count()).select_from(User))
    rows = (await session.scalars(select(User).order_by(User.id).limit(limit).offset(offset))).all()
    data = [
        UserPublic.model_validate(u, from_attributes=True).model_dump(mode="json") for u in rows
    ]
    return {"data": data, "count": int(total or 0)}


@router.post(
    "",
    status_code=status.HTTP_201_CREATED,
    summary="Create a user; the answer holds its token, shown once",
    response_model=UserCreated,
)
async def create_user_route(
    me: EngineerUser, session: SessionDep, settings: SettingsDep, body: UserCreate
) -> dict[str, Any]:
    # Invalid names raise InvalidInput (422), a taken name UserExists (409).
    user, token = await create_user(
        session,
        body.name,
        parse_role(body.role),
        settings.secret_key.get_secret_value(),
        expires_at=token_expiry(body.expires_in_days),
    )
    audit.record(
        session,
        actor=audit.Actor.of(me),
        kind="user",
        entity_id=user.id,
        action="create",
        old=None,
        new={"name": user.name, "role": user.role, "token_label": "created"},
        reason=body.reason,
    )
    return {
        "user": UserPublic.model_validate(user, from_attributes=True).model_dump(mode="json"),
        "token": token,
    }


@router.delete(
    "/{name}", summary="Disable a user and revoke their tokens", response_model=UserDisabled
)
async def delete_user(
    me: EngineerUser,
    session: SessionDep,
    name: NameStr,
    reason: Annotated[
        str | None, Query(max_length=audit.MAX_REASON_LENGTH, description="Why (audit trail)")
    ] = None,
) -> dict[str, Any]:
    user = await session.scalar(select(User).where(User.name == name))
    if user is None:
        raise NotFound(f"no user named {name!r}")
    if user.name == me.name:
        raise Conflict("you cannot disable yourself")
    user.disabled = True
    await users_changed(session, {user.id})
    n = await session.scalar(
        select(func.count()).select_from(ApiToken).where(ApiToken.user_id == user.id)
    )
    for tok in (await session.scalars(select(ApiToken).where(ApiToken.user_id == user.id))).all():
        tok.revoked = True
    audit.record(
        session,
        actor=audit.Actor.of(me),
        kind="user",
        entity_id=user.id,
        action="disable",
        old={"name": name, "disabled": False},
        new={"name": name, "disabled": True, "tokens_revoked": int(n or 0)},
        reason=reason,
    )
    return {"name": name, "disabled": True, "tokens_revoked": int(n or 0)}


@router.patch("/{name}", summary="Change a user's role (engineer)", response_model=UserPublic)
async def update_user_role(
    me: EngineerUser, session: SessionDep, name: NameStr, body: UserRoleIn
) -> dict[str, Any]:
    user = await session.scalar(select(User).where(User.name == name))
    if user is None:
        raise NotFound(f"no user named {name!r}")
    if user.name == me.name and body.role != user.role:
        raise Conflict("you cannot change your own role")
    old_role = user.role
    user.role = parse_role(body.role).name
    if old_role != user.role:
        await users_changed(session, {user.id})
        audit.record(
            session,
            actor=audit.Actor.of(me),
            kind="user",
            entity_id=user.id,
            action="role",
            old={"name": name, "role": old_role},
            new={"name": name, "role": user.role},
            reason=body.reason,
        )
    await session.flush()
    return UserPublic.model_validate(user, from_attributes=True).model_dump(mode="json")


async def _user_named(session: Any, name: str) -> User:
    user = await session.scalar(select(User).where(User.name == name))
    if user is None:
        raise NotFound(f"no user named {name!r}")
    return user


@router.get(
    "/{name}/tokens",
    summary="A user's tokens (prefix, label, dates, state; never the secret)",
    response_model=Page[TokenPublic],
)
async def read_tokens(
    _: EngineerUser, session: SessionDep, name: NameStr, limit: Limit = 100, offset: Offset = 0
) -> Page[TokenPublic]:
    user = await _user_named(session, name)
    where = ApiToken.user_id == user.id
    total = await session.scalar(select(func.count()).select_from(ApiToken).where(where))
    rows = (
        await session.scalars(
            select(ApiToken).where(where).order_by(ApiToken.id).limit(limit).offset(offset)
        )
    ).all()
    return Page[TokenPublic](data=[TokenPublic.of(r) for r in rows], count=int(total or 0))


@router.post(
    "/{name}/tokens",
    status_code=status.HTTP_201_CREATED,
    summary="Issue a token for a user, optionally expiring; the answer holds it, shown once",
    response_model=TokenCreated,
)
async def create_token(
    me: EngineerUser, session: SessionDep, settings: SettingsDep, name: NameStr, body: TokenCreate
) -> TokenCreated:
    user = await _user_named(session, name)
    if user.disabled:
        raise Conflict(f"user {name!r} is disabled")
    secret = settings.secret_key.get_secret_value()
    token = await issue_token(
        session, user, secret, label=body.label, expires_at=token_expiry(body.expires_in_days)
    )
    row = await session.scalar(
        select(ApiToken).where(ApiToken.token_hash == hash_token(token, secret))
    )
    assert row is not None
    info = TokenPublic.of(row)
    audit.record(
        session,
        actor=audit.Actor.of(me),
        kind="token",
        entity_id=row.id,
        action="create",
        old=None,
        new={
            "user": name,
            "label": row.label,
            "expires_at": info.model_dump(mode="json")["expires_at"],
        },
        reason=None,
    )
    return TokenCreated(token=token, info=info)


@router.delete(
    "/{name}/tokens/{token_id}",
    summary="Revoke one token of a user",
    response_model=TokenPublic,
)
async def revoke_token(
    me: EngineerUser, session: SessionDep, name: NameStr, token_id: DbId
) -> TokenPublic:
    user = await _user_named(session, name)
    row = await session.get(ApiToken, token_id)
    if row is None or row.user_id != user.id:
        raise NotFound(f"user {name!r} has no token {token_id}")
    if not row.revoked:
        row.revoked = True
        await users_changed(session, {user.id})
        audit.record(
            session,
            actor=audit.Actor.of(me),
            kind="token",
            entity_id=row.id,
            action="revoke",
            old={"user": name, "revoked": False},
            new={"user": name, "revoked": True},
            reason=None,
        )
    await session.flush()
    return TokenPublic.of(row)
