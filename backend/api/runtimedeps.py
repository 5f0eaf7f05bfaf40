"""Dependencies that fetch the objects of the running system: the runtime, the settings,
the database and a request's session, the cell, the simulator, the 3D view, the read cache.

This module is the one place that knows where the app keeps its
:class:`~backend.runtime.CellRuntime` (:func:`install_runtime`, :func:`runtime_of`);
handlers, the WebSocket and services get what they need from these dependencies (the
sign-in and the roles are :mod:`backend.api.deps`, which names these too).

They are ``async def`` although they never wait: FastAPI runs a plain ``def`` dependency
in a worker thread, a thread hop per dependency and request (a quarter of a cached read's
busy time on the event loop, and GIL hand-overs with the simulator's threads).
"""

from __future__ import annotations

from collections.abc import AsyncIterator, Awaitable, Callable, Hashable, Iterable
from typing import TYPE_CHECKING, Annotated, Any, TypeVar

from fastapi import Depends, FastAPI
from fastapi.requests import HTTPConnection
from sqlalchemy.ext.asyncio import AsyncSession

from backend.api.errors import ApiError
from backend.cell import Cell
from backend.db.models import Role, User
from backend.db.session import Database
from backend.readcache import ReadCache
from backend.runtime import CellRuntime
from backend.settings import Settings

if TYPE_CHECKING:
    from backend.view3d import View3D
    from robot.sim import SimEngine

__all__ = [
    "PURE_DEPENDENCIES",
    "CellDep",
    "DatabaseDep",
    "ReadCacheDep",
    "RuntimeDep",
    "SessionDep",
    "SettingsDep",
    "SimDep",
    "View3DDep",
    "get_cell",
    "get_database",
    "get_read_cache",
    "get_runtime",
    "get_session",
    "get_settings",
    "get_sim_or_none",
    "get_view3d",
    "install_runtime",
    "read_through",
    "runtime_of",
]


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


def get_settings(conn: HTTPConnection) -> Settings:
    return conn.app.state.settings


async def _runtime_dependency(conn: HTTPConnection) -> CellRuntime:
    """:func:`get_runtime` as a dependency (on the event loop, no worker thread)."""
    return get_runtime(conn)


async def _settings_dependency(conn: HTTPConnection) -> Settings:
    """:func:`get_settings` as a dependency (on the event loop, no worker thread)."""
    return get_settings(conn)


async def get_database(conn: HTTPConnection) -> Database:
    return get_runtime(conn).database


async def get_cell(conn: HTTPConnection) -> Cell:
    return get_runtime(conn).cell


async def get_sim_or_none(conn: HTTPConnection) -> SimEngine | None:
    """The simulation engine, or None when the cell drives real (or ideal) hardware."""
    return get_runtime(conn).sim


async def get_view3d(conn: HTTPConnection) -> View3D | None:
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


async def get_read_cache(conn: HTTPConnection) -> ReadCache:
    cache: ReadCache = get_runtime(conn).read_cache
    return cache


_T = TypeVar("_T")


async def read_through(
    cache: ReadCache, db: Database, user: User, key: Hashable, *, tables: Iterable[str],
    read: Callable[[AsyncSession], Awaitable[_T]],
) -> _T:  # fmt: skip
    """``read(session)`` through the runtime's read cache (:mod:`backend.readcache`): the
    answer of ``key`` if fresh and read for a role no stronger than ``user``'s, else read
    in a session of its own (an API connection slot only on a miss); dropped when one of
    ``tables`` is written.  The caller's role dependency has already accepted ``user``;
    the value returned is shared, not to be mutated."""

    async def fresh() -> _T:
        async with db.api_slot(), db.session() as session:
            return await read(session)

    return await cache.get_or_read(key, role=Role[user.role], topics=tables, read=fresh)


# The simulator and the 3D view would load MuJoCo and viser at start-up: written as Any here
# (FastAPI only needs the dependency); the functions above carry the precise types.
RuntimeDep = Annotated[CellRuntime, Depends(_runtime_dependency)]
SettingsDep = Annotated[Settings, Depends(_settings_dependency)]
DatabaseDep = Annotated[Database, Depends(get_database)]
SimDep = Annotated[Any, Depends(get_sim_or_none)]
View3DDep = Annotated[Any, Depends(get_view3d)]
SessionDep = Annotated[AsyncSession, Depends(get_session, scope="function")]
CellDep = Annotated[Cell, Depends(get_cell)]
ReadCacheDep = Annotated[ReadCache, Depends(get_read_cache)]


#: Dependencies that only fetch an object of the running system (and answer 503 while the
#: cell is not running, which the fast path checks itself): what a route the fast path
#: answers may depend on besides its :class:`RoleCheck` (``backend.api.fastpath``).
PURE_DEPENDENCIES: frozenset[Callable[..., Any]] = frozenset(
    {
        _runtime_dependency,
        _settings_dependency,
        get_database,
        get_cell,
        get_sim_or_none,
        get_view3d,
        get_read_cache,
    }
)
