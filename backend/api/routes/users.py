"""Users and tokens (engineer role)."""

from __future__ import annotations

from datetime import datetime
from typing import Any

from fastapi import APIRouter, status
from pydantic import BaseModel, Field
from sqlalchemy import func, select

from backend.api.deps import EngineerUser, SessionDep, SettingsDep, ViewerUser
from backend.api.errors import ApiError
from backend.auth import create_user, parse_role
from backend.db.models import ApiToken, User

router = APIRouter(prefix="/users", tags=["users"])


class UserCreate(BaseModel):
    name: str = Field(min_length=1, max_length=64)
    role: str = Field(description="viewer, operator or engineer")


class UserPublic(BaseModel):
    id: int
    name: str
    role: str
    created_at: datetime
    disabled: bool


@router.get("/me", summary="The user owning the token")
async def read_me(user: ViewerUser) -> dict[str, Any]:
    return {"name": user.name, "role": user.role}


@router.get("", summary="All users")
async def read_users(_: EngineerUser, session: SessionDep) -> dict[str, Any]:
    rows = (await session.scalars(select(User).order_by(User.id))).all()
    data = [
        UserPublic.model_validate(u, from_attributes=True).model_dump(mode="json") for u in rows
    ]
    return {"data": data, "count": len(data)}


@router.post(
    "",
    status_code=status.HTTP_201_CREATED,
    summary="Create a user; the answer holds its token, shown once",
)
async def create_user_route(
    _: EngineerUser, session: SessionDep, settings: SettingsDep, body: UserCreate
) -> dict[str, Any]:
    try:
        role = parse_role(body.role)
        user, token = await create_user(
            session, body.name, role, settings.secret_key.get_secret_value()
        )
    except ValueError as exc:
        code = 409 if "already exists" in str(exc) else 422
        raise ApiError(code, "conflict" if code == 409 else "validation_error", str(exc)) from None
    return {
        "user": UserPublic.model_validate(user, from_attributes=True).model_dump(mode="json"),
        "token": token,
    }


@router.delete("/{name}", summary="Disable a user and revoke their tokens")
async def delete_user(me: EngineerUser, session: SessionDep, name: str) -> dict[str, Any]:
    user = await session.scalar(select(User).where(User.name == name))
    if user is None:
        raise ApiError(404, "not_found", f"no user named {name!r}")
    if user.name == me.name:
        raise ApiError(409, "conflict", "you cannot disable yourself")
    user.disabled = True
    n = await session.scalar(
        select(func.count()).select_from(ApiToken).where(ApiToken.user_id == user.id)
    )
    for tok in (await session.scalars(select(ApiToken).where(ApiToken.user_id == user.id))).all():
        tok.revoked = True
    return {"name": name, "disabled": True, "tokens_revoked": int(n or 0)}
