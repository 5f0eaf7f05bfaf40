"""Shared dependencies: database session, current user with a minimum role, the cell."""

from __future__ import annotations

from collections.abc import AsyncIterator, Callable, Coroutine
from typing import Annotated, Any

from fastapi import Depends, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from sqlalchemy.ext.asyncio import AsyncSession

from backend.api.errors import ApiError
from backend.auth import authenticate
from backend.cell import Cell
from backend.db.models import Role, User
from backend.db.session import Database
from backend.settings import Settings

__all__ = [
    "CellDep",
    "DatabaseDep",
    "EngineerUser",
    "OperatorUser",
    "SessionDep",
    "SettingsDep",
    "ViewerUser",
    "require_role",
]

_bearer = HTTPBearer(
    auto_error=False, description="API token from `visioncell user add` or the start-up banner"
)


def get_settings(request: Request) -> Settings:
    return request.app.state.settings


def get_database(request: Request) -> Database:
    return request.app.state.db


def get_cell(request: Request) -> Cell:
    cell = getattr(request.app.state, "cell", None)
    if cell is None:
        raise ApiError(503, "unavailable", "the cell is not running")
    return cell


async def get_session(
    db: Annotated[Database, Depends(get_database)],
) -> AsyncIterator[AsyncSession]:
    async with db.session() as session:
        yield session


SettingsDep = Annotated[Settings, Depends(get_settings)]
DatabaseDep = Annotated[Database, Depends(get_database)]
SessionDep = Annotated[AsyncSession, Depends(get_session)]
CellDep = Annotated[Cell, Depends(get_cell)]


def require_role(role: Role) -> Callable[..., Coroutine[Any, Any, User]]:
    """Dependency: the token's user, who must hold at least ``role``."""

    async def current_user(
        settings: SettingsDep,
        db: DatabaseDep,
        creds: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)],
    ) -> User:
        if not settings.auth_enabled:
            return User(id=0, name="anonymous", role=Role.engineer.name)
        if creds is None or creds.scheme.lower() != "bearer":
            raise ApiError(
                401,
                "unauthorized",
                "missing bearer token (Authorization: Bearer TOKEN)",
                headers={"WWW-Authenticate": "Bearer"},
            )
        async with db.session() as session:
            user = await authenticate(
                session, creds.credentials, settings.secret_key.get_secret_value()
            )
        if user is None:
            raise ApiError(
                401,
                "unauthorized",
                "invalid or revoked token",
                headers={"WWW-Authenticate": "Bearer"},
            )
        if Role[user.role] < role:
            raise ApiError(
                403,
                "forbidden",
                f"this needs the {role.name} role; user {user.name!r} is {user.role}",
            )
        return user

    return current_user


ViewerUser = Annotated[User, Depends(require_role(Role.viewer))]
OperatorUser = Annotated[User, Depends(require_role(Role.operator))]
EngineerUser = Annotated[User, Depends(require_role(Role.engineer))]
