"""Shared dependencies: the runtime, database session, current user with a minimum role,
the cell, the simulator.

This module is the one place that knows where the app keeps its
:class:`~backend.runtime.CellRuntime` (:func:`install_runtime`, :func:`runtime_of`);
handlers, the WebSocket and services get what they need from these dependencies.
"""

from __future__ import annotations

from collections.abc import AsyncIterator, Awaitable, Callable, Coroutine, Hashable, Iterable
from typing import TYPE_CHECKING, Annotated, Any, TypeVar

from fastapi import Depends, FastAPI
from fastapi.requests import HTTPConnection
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from sqlalchemy.ext.asyncio import AsyncSession

from backend.api.errors import ApiError
from backend.auth import authenticate_with_expiry, hash_token, well_formed
from backend.cell import Cell
from backend.db.models import Role, User
from backend.db.session import Database
from backend.readcache import ReadCache
from backend.settings import Settings
from backend.throttle import SignInThrottle, TooManyAttempts

if TYPE_CHECKING:
    from backend.runtime import CellRuntime
    from backend.view3d import View3D
    from robot.sim import SimEngine

__all__ = [
    "CellDep",
    "DatabaseDep",
    "EngineerUser",
    "OperatorUser",
    "RuntimeDep",
    "SessionDep",
    "SettingsDep",
    "SimDep",
    "View3DDep",
    "ViewerUser",
    "client_address",
    "get_cell",
    "get_database",
    "get_runtime",
    "get_settings",
    "install_runtime",
    "require_role",
    "runtime_of",
    "signin_throttle",
]

_bearer = HTTPBearer(
    auto_error=False, description="API token from `visioncell user add` or the start-up banner"
)


def install_runtime(
    app: FastAPI, runtime: CellRuntime | None, *, settings: Settings | None = None
) -> None:
    """Make ``runtime`` the one the app's dependencies serve (None: not running)."""
    app.state.runtime = runtime
    if settings is not None:
        app.state.settings = settings
    elif runtime is not None:
        app.state.settings = runtime.settings


def runtime_of(app: FastAPI) -> CellRuntime | None:
    """The runtime an app serves (None before start-up and after shutdown)."""
    return getattr(app.state, "runtime", None)


def get_runtime(conn: HTTPConnection) -> CellRuntime:
    """The running :class:`CellRuntime`, or 503 when the cell is not running."""
    rt = runtime_of(conn.app)
    if rt is None or not rt.running:
        raise ApiError(503, "unavailable", "the cell is not running")
    return rt


def client_address(conn: HTTPConnection) -> str:
    """The peer address a request or WebSocket came from (the key of the sign-in throttle)."""
    return conn.client.host if conn.client is not None else "unknown"


def signin_throttle(conn: HTTPConnection) -> SignInThrottle:
    """The running cell's sign-in throttle (503 when the cell is not running)."""
    return get_runtime(conn).signin_throttle


def too_many_attempts(exc: TooManyAttempts) -> ApiError:
    """The 429 answer of a blocked client."""
    return ApiError(
        429,
        "too_many_attempts",
        str(exc),
        headers={"Retry-After": str(exc.retry_after_s)},
    )


def get_settings(conn: HTTPConnection) -> Settings:
    return conn.app.state.settings


def get_database(conn: HTTPConnection) -> Database:
    return get_runtime(conn).database


def get_cell(conn: HTTPConnection) -> Cell:
    return get_runtime(conn).cell


def get_sim_or_none(conn: HTTPConnection) -> SimEngine | None:
    """The simulation engine, or None when the cell drives real (or ideal) hardware."""
    return get_runtime(conn).sim


def get_view3d(conn: HTTPConnection) -> View3D | None:
    """The 3D view, or None when it is off (or the cell is not running)."""
    rt = runtime_of(conn.app)
    return rt.view3d if rt is not None and rt.running else None


async def get_session(
    db: Annotated[Database, Depends(get_database)],
) -> AsyncIterator[AsyncSession]:
    """The request's unit of work: committed whole, or rolled back, *before* the response
    is sent (``SessionDep`` has ``scope="function"``).  FastAPI's default for a dependency
    with ``yield`` runs its exit after the response: a client could be told 201, read the
    row back at once and get 404 (CI saw it on the calibration samples upload), and a
    commit that failed then was lost without the client knowing."""
    async with db.api_slot(), db.session() as session:  # leave connections for the cell
        yield session


def get_read_cache(conn: HTTPConnection) -> ReadCache:
    cache: ReadCache = get_runtime(conn).read_cache
    return cache


_T = TypeVar("_T")


async def read_through(
    cache: ReadCache, db: Database, user: User, key: Hashable, *, tables: Iterable[str],
    read: Callable[[AsyncSession], Awaitable[_T]],
) -> _T:  # fmt: skip
    """``read(session)`` through the runtime's read cache (:mod:`backend.readcache`): the
    answer of ``key`` if fresh and read for a role no stronger than ``user``'s, else read
    in a session of its own (an API connection slot only on a miss).  The caller's role
    dependency has already accepted ``user``; the value returned is shared, not to be
    mutated."""

    async def fresh() -> _T:
        async with db.api_slot(), db.session() as session:
            return await read(session)

    return await cache.get_or_read(key, role=Role[user.role], tables=tables, read=fresh)


# Types the runtime's module would import at start-up are written as Any here (FastAPI only
# needs the dependency); the functions above carry the precise types.
RuntimeDep = Annotated[Any, Depends(get_runtime)]
SettingsDep = Annotated[Settings, Depends(get_settings)]
DatabaseDep = Annotated[Database, Depends(get_database)]
SimDep = Annotated[Any, Depends(get_sim_or_none)]
View3DDep = Annotated[Any, Depends(get_view3d)]
SessionDep = Annotated[AsyncSession, Depends(get_session, scope="function")]
CellDep = Annotated[Cell, Depends(get_cell)]
ReadCacheDep = Annotated[ReadCache, Depends(get_read_cache)]


async def _signed_in(
    conn: HTTPConnection, db: Database, token: str, settings: Settings
) -> User | None:
    """The user of ``token``: from the runtime's short-lived sign-in cache
    (:mod:`backend.authcache`), else from the database (then cached)."""
    secret = settings.secret_key.get_secret_value()
    cache = get_runtime(conn).auth_cache
    if not well_formed(token):
        return None
    key = hash_token(token, secret)
    user = cache.get(key)
    if user is not None:
        return user
    generation = cache.generation
    async with db.api_slot(), db.session() as session:
        found = await authenticate_with_expiry(session, token, secret)
    if found is None:
        return None
    cache.put(key, found[0], found[1], generation=generation)
    return found[0]


def require_role(role: Role) -> Callable[..., Coroutine[Any, Any, User]]:
    """Dependency: the token's user, who must hold at least ``role``."""

    async def current_user(
        conn: HTTPConnection,
        settings: SettingsDep,
        db: DatabaseDep,
        creds: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)],
    ) -> User:
        if not settings.auth_enabled:
            return User(id=0, name="anonymous", role=Role.engineer.name)
        throttle, client = signin_throttle(conn), client_address(conn)
        try:
            throttle.check(client)  # blocked: refused even with a correct token
        except TooManyAttempts as exc:
            raise too_many_attempts(exc) from None
        if creds is None or creds.scheme.lower() != "bearer":
            raise ApiError(
                401,
                "unauthorized",
                "missing bearer token (Authorization: Bearer TOKEN)",
                headers={"WWW-Authenticate": "Bearer"},
            )
        user = await _signed_in(conn, db, creds.credentials, settings)
        if user is None:
            throttle.failure(client)
            raise ApiError(
                401,
                "unauthorized",
                "invalid, expired or revoked token",
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
