"""Shared dependencies: the current user with a minimum role (the sign-in and its
refusals), and, named here too, the running system's objects
(:mod:`backend.api.runtimedeps`: the runtime, settings, database session, the cell, the
simulator).

The sign-in rule is one class, :class:`RoleCheck`; the fast path of the hot reads
(:mod:`backend.api.fastpath`) reads a route's :class:`RoleCheck` and asks the same sign-in
cache through :func:`cached_role`; the emergency stop signs in from memory alone
(:func:`estop_user`, :func:`known_user`).
"""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends
from fastapi.requests import HTTPConnection
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from backend.api.errors import ApiError
from backend.api.runtimedeps import (
    PURE_DEPENDENCIES,
    CellDep,
    DatabaseDep,
    ReadCacheDep,
    RuntimeDep,
    SessionDep,
    SettingsDep,
    SimDep,
    View3DDep,
    get_cell,
    get_database,
    get_read_cache,
    get_runtime,
    get_session,
    get_settings,
    get_sim_or_none,
    get_view3d,
    install_runtime,
    read_through,
    runtime_of,
)
from backend.auth import authenticate_with_expiry, hash_token, well_formed
from backend.caches import Lookup, SignIn
from backend.db.models import Role, User
from backend.db.session import Database
from backend.settings import Settings
from backend.throttle import SignInThrottle, TooManyAttempts

__all__ = [
    "PURE_DEPENDENCIES",
    "SIGNED_IN_BEFORE_BODY",
    "CellDep",
    "DatabaseDep",
    "EStopUser",
    "EngineerUser",
    "OperatorUser",
    "ReadCacheDep",
    "RoleCheck",
    "RuntimeDep",
    "SessionDep",
    "SettingsDep",
    "SimDep",
    "View3DDep",
    "ViewerUser",
    "cached_role",
    "client_address",
    "estop_user",
    "get_cell",
    "get_database",
    "get_read_cache",
    "get_runtime",
    "get_session",
    "get_settings",
    "get_sim_or_none",
    "get_view3d",
    "install_runtime",
    "known_user",
    "read_through",
    "require_role",
    "runtime_of",
    "signed_in",
    "signin_throttle",
]

#: Scope key under which the edge leaves the user it signed in before the body was read.
SIGNED_IN_BEFORE_BODY = "visioncell.signed_in_before_body"

_bearer = HTTPBearer(
    auto_error=False, description="API token from `visioncell user add` or the start-up banner"
)


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


def _lookup(db: Database, token: str, secret: str) -> Lookup:
    """The database sign-in of ``token`` (what the sign-in cache runs on a miss): its user
    and expiry, or None when refused."""

    async def lookup() -> SignIn | None:
        async with db.api_slot(), db.session() as session:
            return await authenticate_with_expiry(session, token, secret)

    return lookup


async def _signed_in(
    conn: HTTPConnection, db: Database, token: str, settings: Settings
) -> User | None:
    """The user of ``token``: from the runtime's short-lived sign-in cache
    (:mod:`backend.caches`), else from the database (then cached)."""
    secret = settings.secret_key.get_secret_value()
    cache = get_runtime(conn).auth_cache
    if not well_formed(token):
        return None
    return await cache.sign_in(hash_token(token, secret), _lookup(db, token, secret))


async def signed_in(conn: HTTPConnection, token: str) -> User | None:
    """The user ``token`` signs in, as :class:`RoleCheck` finds it (the sign-in cache,
    else the database; no throttle): for the console's WebSocket."""
    return await _signed_in(conn, get_runtime(conn).database, token, get_settings(conn))


class RoleCheck:
    """Dependency: the token's user, who must hold at least :attr:`role`
    (``Depends(require_role(Role.operator))``).

    Refusals, in order: 429 for a client address the sign-in throttle blocks (even with a
    correct token), 401 without a bearer token or with a bad, expired or revoked one (a
    failure for the throttle), 403 for a weaker role.  With ``auth_enabled`` off every
    caller is an anonymous engineer.  The fast path (``backend.api.fastpath``) takes a
    route's minimum role from its :class:`RoleCheck` and asks :meth:`allows`."""

    def __init__(self, role: Role) -> None:
        if not isinstance(role, Role):
            raise TypeError(f"role must be a Role, got {role!r}")
        #: The weakest role let through.
        self.role = role

    def allows(self, role: Role) -> bool:
        """Whether a user holding ``role`` may pass."""
        return role >= self.role

    async def __call__(
        self,
        conn: HTTPConnection,
        settings: SettingsDep,
        db: DatabaseDep,
        creds: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)],
    ) -> User:
        early = conn.scope.get(SIGNED_IN_BEFORE_BODY)
        if isinstance(early, User):  # the edge signed this request in before its body
            return self._allowed(early)
        return await self.sign_in(conn, settings=settings, db=db, creds=creds)

    async def check_before_body(self, conn: HTTPConnection) -> User:
        """This check for a request whose body has not been read yet (the edge,
        :mod:`backend.api.edge`): the same sign-in and refusals as the dependency, from
        the request's headers alone; the user is kept in the request's scope so that the
        dependency does not sign in a second time."""
        settings = get_settings(conn)
        db = get_runtime(conn).database
        user = await self.sign_in(conn, settings=settings, db=db, creds=await _bearer(conn))
        conn.scope[SIGNED_IN_BEFORE_BODY] = user
        return user

    def _allowed(self, user: User) -> User:
        if not self.allows(Role[user.role]):
            raise ApiError(
                403,
                "forbidden",
                f"this needs the {self.role.name} role; user {user.name!r} is {user.role}",
            )
        return user

    async def sign_in(
        self,
        conn: HTTPConnection,
        *,
        settings: Settings,
        db: Database,
        creds: HTTPAuthorizationCredentials | None,
    ) -> User:
        """The refusals of the class docstring, in order; the user when none applies."""
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
        return self._allowed(user)

    def __repr__(self) -> str:
        return f"RoleCheck({self.role.name})"


def require_role(role: Role) -> RoleCheck:
    """Dependency: the token's user, who must hold at least ``role`` (:class:`RoleCheck`)."""
    return RoleCheck(role)


async def cached_role(conn: HTTPConnection) -> Role | None:
    """The role a :class:`RoleCheck` would find for this request from memory alone: the
    anonymous engineer when ``auth_enabled`` is off; else the role of a well-formed bearer
    token the sign-in cache holds valid (the token's expiry checked on this hit), from an
    address the throttle does not block.  None in every other case (a token the cache does
    not hold, none, a blocked address, the cell not running): the dependency itself must
    decide, from the database, and answer any refusal."""
    settings = get_settings(conn)
    if not settings.auth_enabled:
        return Role.engineer
    rt = runtime_of(conn.app)
    if rt is None or not rt.running:
        return None
    try:
        rt.signin_throttle.check(client_address(conn))
    except TooManyAttempts:
        return None
    creds = await _bearer(conn)
    if creds is None or creds.scheme.lower() != "bearer" or not well_formed(creds.credentials):
        return None
    user = rt.auth_cache.get(hash_token(creds.credentials, settings.secret_key.get_secret_value()))
    return None if user is None else Role[user.role]


def known_user(conn: HTTPConnection, token: str | None) -> User | None:
    """The user of a bearer ``token`` known from memory alone: the sign-in cache's entry
    (no database work), else a token this process saw valid within the hour
    (:mod:`backend.knowntokens`); the anonymous engineer with ``auth_enabled`` off.  None
    for anything else (no token, a malformed or unknown one, the cell not running)."""
    settings = get_settings(conn)
    if not settings.auth_enabled:
        return User(id=0, name="anonymous", role=Role.engineer.name)
    rt = runtime_of(conn.app)
    if rt is None or not rt.running or token is None or not well_formed(token):
        return None
    key = hash_token(token, settings.secret_key.get_secret_value())
    user = rt.auth_cache.get(key)
    if user is not None:
        return user
    known = rt.known_tokens.get(key)
    return None if known is None else User(id=known.user_id, name=known.user, role=known.role)


async def estop_user(
    conn: HTTPConnection,
    settings: SettingsDep,
    creds: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)],
) -> User:
    """Dependency of the emergency stop: the token's user, from memory only.

    Any signed-in role may stop the cell.  The token is accepted when the sign-in cache
    holds it or this process saw it valid in the last hour (:mod:`backend.knowntokens`):
    no database read, and no throttle for such a token, so a database outage or a flood of
    bad tokens from the same address cannot delay or refuse the stop.  A token not known
    so gets the usual refusals: 429 while the address is blocked, else 401 (counted as a
    failure), so this route is no way to test tokens faster than any other."""
    rt = get_runtime(conn)
    token = creds.credentials if creds is not None and creds.scheme.lower() == "bearer" else None
    user = known_user(conn, token)
    if user is not None:
        return user
    client = client_address(conn)
    try:
        rt.signin_throttle.check(client)
    except TooManyAttempts as exc:
        raise too_many_attempts(exc) from None
    if token is None:
        raise ApiError(
            401,
            "unauthorized",
            "missing bearer token (Authorization: Bearer TOKEN)",
            headers={"WWW-Authenticate": "Bearer"},
        )
    rt.signin_throttle.failure(client)
    raise ApiError(
        401,
        "unauthorized",
        "invalid, expired or revoked token (or one this cell has not seen signed in for an "
        "hour: sign in once, e.g. open the console)",
        headers={"WWW-Authenticate": "Bearer"},
    )


ViewerUser = Annotated[User, Depends(require_role(Role.viewer))]
EStopUser = Annotated[User, Depends(estop_user)]
OperatorUser = Annotated[User, Depends(require_role(Role.operator))]
EngineerUser = Annotated[User, Depends(require_role(Role.engineer))]
