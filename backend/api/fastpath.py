"""A fast path for the console's hot reads: a GET answered from memory, byte for byte what
FastAPI would answer, without FastAPI's routing, dependencies and validation.

A cached read cost about a millisecond of CPU on a quiet machine and 4-5 ms on a loaded
one (``benchmarks/load.py --route-cpu``), nearly all of it the framework's (routing
through every route, solving each dependency, validating and serialising the answer),
on the event loop that shares the GIL with the simulator and the vision.
:class:`FastReads`, a pure ASGI layer just in front of FastAPI's router (inside the
security-header, CORS and URL-length layers, so those apply unchanged), answers a
:class:`FastRead` route itself when it can:

- only ``GET`` of the route's exact path, with a query string it has validated before
  with the route's own query parameters (FastAPI's validation, kept per query string,
  at most :data:`MAX_QUERIES` per route);
- only when the sign-in is known from memory: :func:`backend.api.deps.cached_role`
  (the sign-in cache, the token's expiry checked on this hit, the sign-in throttle), and
  the role passes the route's own :class:`~backend.api.deps.RoleCheck` (found among the
  route's dependencies, never restated here);
- only when the route's :attr:`FastRead.answer` can answer from memory: a read-cache
  entry (:meth:`backend.readcache.ReadCache.peek`, the same freshness and role rule as
  the handler's read) or the cell's in-memory state;
- the answer is rendered by FastAPI's own serialisation of that route (response model,
  response class) once per :attr:`Fresh.version` and the bytes reused until the version
  changes: once per read-cache entry for the database lists.

Anything else falls through to FastAPI unchanged: a read-cache miss, an unknown, expired
or revoked token (FastAPI answers the 401), a weaker role (403), a blocked address (429),
another route, another method, a query string it has not validated.  At start-up the layer
refuses a route whose dependencies it does not know (a check it would skip), and one that
another route would shadow.  ``Settings.fast_reads`` (``VISIONCELL_FAST_READS``) turns it off.
"""

from __future__ import annotations

import copy
from collections.abc import Awaitable, Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from fastapi.datastructures import DefaultPlaceholder
from fastapi.dependencies.models import Dependant
from fastapi.dependencies.utils import request_params_to_args
from fastapi.requests import HTTPConnection
from fastapi.routing import iter_route_contexts, serialize_response
from starlette.datastructures import QueryParams
from starlette.responses import Response
from starlette.routing import BaseRoute, WebSocketRoute
from starlette.types import ASGIApp, Receive, Scope, Send

from backend.api.deps import PURE_DEPENDENCIES, RoleCheck, cached_role, runtime_of
from backend.db.models import Role
from backend.settings import Settings

if TYPE_CHECKING:
    from backend.runtime import CellRuntime

__all__ = [
    "MAX_KEPT_BYTES",
    "MAX_QUERIES",
    "MAX_QUERY_BYTES",
    "FastRead",
    "FastReads",
    "FastRequest",
    "Fresh",
    "fast_reads_of",
]

#: Distinct query strings kept per route (their validated parameters and answer).
MAX_QUERIES = 64
#: Longest query string the fast path looks at, bytes (longer ones go to FastAPI).
MAX_QUERY_BYTES = 1024
#: Most bytes of rendered answers kept over all routes (beyond it answers are still
#: rendered and sent, but not kept).
MAX_KEPT_BYTES = 32 << 20


@dataclass(frozen=True)
class FastRequest:
    """What a :attr:`FastRead.answer` gets."""

    #: The running cell.
    runtime: CellRuntime
    #: The app's settings (what ``SettingsDep`` gives the handler).
    settings: Settings
    #: The caller's role, accepted by the route's :class:`RoleCheck` (None: the route
    #: needs no sign-in).
    role: Role | None
    #: The route's query parameters, validated by FastAPI's rules, by parameter name.
    params: Mapping[str, Any]


@dataclass(frozen=True)
class Fresh:
    """An answer the fast path may give now."""

    #: Equal versions give equal answers (compared with ``==``; a read-cache
    #: :class:`~backend.readcache.Answer` compares by identity).
    version: Any
    #: The handler's return value for this version (called when the version is new).
    content: Callable[[], Any]
    #: Whether ``version`` still holds after ``content()`` ran (None: always); when it
    #: does not, the answer is sent but not kept.
    still: Callable[[], bool] | None = None
    #: The version holds objects that may change in place (a job's ``params``): what is
    #: kept with the answer is a deep copy of it.
    copy_version: bool = False

    @classmethod
    def of_content(cls, content: Any) -> Fresh:
        """An answer whose version is its content (an in-memory state, compared whole)."""
        return cls(content, lambda: content, copy_version=True)


#: How a route is answered from memory: None when it cannot be (FastAPI answers).
FastAnswer = Callable[[FastRequest], Awaitable[Fresh | None]]


@dataclass(frozen=True)
class FastRead:
    """A GET route the fast path may answer."""

    #: The route's handler (the route is found by it among the app's routes).
    endpoint: Callable[..., Any]
    #: Its answer from memory.
    answer: FastAnswer
    #: Dependencies of this route that only fetch an object (beside
    #: :data:`backend.api.deps.PURE_DEPENDENCIES`).
    providers: tuple[Callable[..., Any], ...] = ()


@dataclass(frozen=True)
class _Snapshot:
    version: Any
    status: int
    headers: tuple[tuple[bytes, bytes], ...]
    body: bytes


@dataclass
class _Slot:
    """One query string of a route: its validated parameters and last answer."""

    params: Mapping[str, Any]
    snapshot: _Snapshot | None = None


@dataclass
class _Route:
    read: FastRead
    context: Any  # fastapi.routing.RouteContext of the route
    check: RoleCheck | None
    query_fields: list[Any]
    slots: dict[bytes, _Slot] = field(default_factory=dict)


def _route_check(
    dependant: Dependant, allowed: frozenset[Callable[..., Any]], what: str
) -> RoleCheck | None:
    """The strongest :class:`RoleCheck` among ``dependant``'s dependencies; ValueError
    for any dependency that is neither one nor in ``allowed`` (a check the fast path
    would skip), or for parameters other than the query's."""
    if dependant.path_params or dependant.header_params or dependant.cookie_params:
        raise ValueError(f"{what}: the fast path answers routes with query parameters only")
    if dependant.body_params:
        raise ValueError(f"{what}: the fast path answers routes without a body only")
    found: list[RoleCheck] = []
    for dep in dependant.dependencies:
        if isinstance(dep.call, RoleCheck):
            found.append(dep.call)
            continue
        if dep.call not in allowed:
            raise ValueError(
                f"{what}: dependency {dep.call!r} is not one the fast path knows "
                "(a RoleCheck or a pure provider)"
            )
        if dep.query_params:
            raise ValueError(f"{what}: dependency {dep.call!r} takes query parameters")
        inner = _route_check(dep, allowed, what)
        if inner is not None:
            found.append(inner)
    return max(found, key=lambda c: c.role) if found else None


def _first_get_route(contexts: Sequence[Any], path: str) -> Any | None:
    """The route Starlette's router would pick for ``GET path`` (its first full match)."""
    for ctx in contexts:
        if isinstance(ctx.original_route, WebSocketRoute):
            continue
        regex = getattr(ctx, "path_regex", None)
        methods = getattr(ctx, "methods", None)
        if regex is not None and regex.match(path) and (methods is None or "GET" in methods):
            return ctx
    return None


def _resolve(routes: Sequence[BaseRoute], reads: Iterable[FastRead]) -> dict[str, _Route]:
    contexts = list(iter_route_contexts(routes))
    out: dict[str, _Route] = {}
    for read in reads:
        name = getattr(read.endpoint, "__qualname__", repr(read.endpoint))
        mine = [
            c for c in contexts
            if getattr(c, "endpoint", None) is read.endpoint and "GET" in (c.methods or ())
        ]  # fmt: skip
        if len(mine) != 1:
            raise ValueError(f"{name}: expected one GET route, found {len(mine)}")
        ctx = mine[0]
        path = ctx.path
        if not isinstance(path, str) or "{" in path:
            raise ValueError(f"{name}: the fast path answers fixed paths only, got {path!r}")
        if _first_get_route(contexts, path) is not ctx:
            raise ValueError(f"{name}: GET {path} is answered by another route first")
        dependant: Dependant = ctx.dependant
        if (
            dependant.request_param_name or dependant.response_param_name
            or dependant.background_tasks_param_name or dependant.http_connection_param_name
            or dependant.websocket_param_name or dependant.security_scopes_param_name
        ):  # fmt: skip
            raise ValueError(f"{name}: the handler takes the request or the response itself")
        allowed = PURE_DEPENDENCIES | frozenset(read.providers)
        check = _route_check(dependant, allowed, name)
        if path in out:
            raise ValueError(f"{name}: GET {path} is listed twice")
        out[path] = _Route(read, ctx, check, list(dependant.query_params))
    return out


async def _render(ctx: Any, content: Any) -> Response:
    """The response FastAPI makes of a handler's return value ``content`` on the route
    ``ctx``: a :class:`Response` as is; else validated and serialised by the route's
    response field (to JSON bytes when the response class is the default, as FastAPI
    does), in the route's response class."""
    if isinstance(content, Response):
        return content
    dump_json = ctx.response_field is not None and isinstance(
        ctx.response_class, DefaultPlaceholder
    )
    body = await serialize_response(
        field=ctx.response_field,
        response_content=content,
        include=ctx.response_model_include,
        exclude=ctx.response_model_exclude,
        by_alias=ctx.response_model_by_alias,
        exclude_unset=ctx.response_model_exclude_unset,
        exclude_defaults=ctx.response_model_exclude_defaults,
        exclude_none=ctx.response_model_exclude_none,
        is_coroutine=True,
        dump_json=dump_json,
    )
    args: dict[str, Any] = {"status_code": ctx.status_code} if ctx.status_code else {}
    if dump_json:
        return Response(content=body, media_type="application/json", **args)
    cls = ctx.response_class
    cls = cls.value if isinstance(cls, DefaultPlaceholder) else cls
    response: Response = cls(body, **args)
    return response


class FastReads:
    """Pure ASGI middleware answering the :class:`FastRead` routes from memory (see the
    module doc); every other request goes to ``app`` unchanged.

    Parameters
    ----------
    app : ASGI app
        What follows (FastAPI's exception layer and router).
    routes : sequence of routes
        The app's routes (``FastAPI.routes``), where each read's route is found.
    reads : iterable of FastRead
        The routes to answer.
    """

    def __init__(
        self, app: ASGIApp, *, routes: Sequence[BaseRoute], reads: Iterable[FastRead]
    ) -> None:
        self.app = app
        self._routes = _resolve(routes, reads)
        self._kept_bytes = 0
        #: Requests answered here, and requests of a fast route handed to FastAPI.
        self.answered = 0
        self.passed = 0

    @property
    def paths(self) -> frozenset[str]:
        """The paths this layer may answer."""
        return frozenset(self._routes)

    def _slot(self, route: _Route, query: bytes) -> _Slot | None:
        slot = route.slots.get(query)
        if slot is not None or len(query) > MAX_QUERY_BYTES:
            return slot
        values, errors = request_params_to_args(route.query_fields, QueryParams(query))
        if errors:
            return None  # FastAPI answers the 422
        if len(route.slots) >= MAX_QUERIES:  # the oldest query string goes
            old = route.slots.pop(next(iter(route.slots)))
            self._forget(old.snapshot)
        slot = route.slots[query] = _Slot(values)
        return slot

    def _forget(self, snap: _Snapshot | None) -> None:
        if snap is not None:
            self._kept_bytes -= len(snap.body)

    async def _answer(self, scope: Scope, route: _Route) -> _Snapshot | None:
        slot = self._slot(route, scope.get("query_string", b""))
        if slot is None:
            return None
        conn = HTTPConnection(scope)
        rt = runtime_of(conn.app)
        if rt is None or not rt.running:
            return None
        role: Role | None = None
        if route.check is not None:
            role = await cached_role(conn)
            if role is None or not route.check.allows(role):
                return None  # the RoleCheck decides, from the database, and refuses
        settings: Settings = conn.app.state.settings
        fresh = await route.read.answer(FastRequest(rt, settings, role, slot.params))
        if fresh is None:
            return None
        snap = slot.snapshot
        if snap is not None and snap.version == fresh.version:
            return snap
        response = await _render(route.context, fresh.content())
        version = copy.deepcopy(fresh.version) if fresh.copy_version else fresh.version
        snap = _Snapshot(
            version, response.status_code, tuple(response.raw_headers), bytes(response.body)
        )
        if (fresh.still is None or fresh.still()) and (
            self._kept_bytes + len(snap.body) <= MAX_KEPT_BYTES
            and route.slots.get(scope.get("query_string", b"")) is slot
        ):
            self._forget(slot.snapshot)
            slot.snapshot = snap
            self._kept_bytes += len(snap.body)
        return snap

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        route = (
            self._routes.get(scope["path"])
            if scope["type"] == "http" and scope["method"] == "GET" and not scope.get("root_path")
            else None
        )
        if route is None:
            await self.app(scope, receive, send)
            return
        snap = await self._answer(scope, route)
        if snap is None:
            self.passed += 1
            await self.app(scope, receive, send)
            return
        self.answered += 1
        # A new list each time: the layers outside may extend it in place (CORS).
        await send(
            {"type": "http.response.start", "status": snap.status, "headers": list(snap.headers)}
        )
        await send({"type": "http.response.body", "body": snap.body})


def fast_reads_of(app: Any) -> FastReads | None:
    """The :class:`FastReads` layer of a started app (None when it has none)."""
    layer = getattr(app, "middleware_stack", None)
    seen: set[int] = set()
    while layer is not None and id(layer) not in seen:
        if isinstance(layer, FastReads):
            return layer
        seen.add(id(layer))
        layer = getattr(layer, "app", None)
    return None
