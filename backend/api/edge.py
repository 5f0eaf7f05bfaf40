"""The edge refuses before it reads: a request's sign-in and size are checked before its
body is read, and the body is counted as it streams in.

:class:`BodyGuard` is a pure ASGI layer in front of FastAPI, so it sees every HTTP
request.  For a request that carries a
body (a ``Content-Length`` above 0, or ``Transfer-Encoding``) it finds the route the
router would pick, and when that route takes a body:

1. if the route needs a role, the route's own :class:`~backend.api.deps.RoleCheck` runs
   now (:meth:`~backend.api.deps.RoleCheck.check_before_body`: the throttle, the sign-in
   cache, the database on a miss), so a request without a valid token gets its 401 (403,
   429) before a byte of its body is read or parsed; the user found is handed to the
   route's dependency, which does not sign in again;
2. a declared ``Content-Length`` over the route's limit is refused with 413 at once;
3. the body is counted as the application reads it: past the limit, or past the declared
   length, the request is refused (413, or 400 for a length that lied) and the application
   is told the client has gone, so it stops reading.

The limits: JSON routes ``Settings.max_json_body_bytes`` (1 MiB), upload routes (a
multipart form: files) ``Settings.max_upload_body_bytes`` (64 MiB).  Every refusal is the
JSON error body ``{"error", "detail"}``.  Requests without a body (every plain GET, the hot
reads) pass untouched and cost no lookup; a route that takes no body (FastAPI never reads
it) is not signed in here either: E-STOP and the reads keep their own path.  What the
server still receives of a refused body is read and dropped by uvicorn, never buffered or
parsed.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from fastapi import params
from fastapi.dependencies.models import Dependant
from fastapi.requests import HTTPConnection
from fastapi.routing import iter_route_contexts
from starlette.routing import BaseRoute, WebSocketRoute
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from backend.api.deps import RoleCheck
from backend.api.errors import ApiError, database_refusal, status_of
from vision.errors import VisionCellError

__all__ = [
    "DEFAULT_JSON_BODY_BYTES",
    "DEFAULT_UPLOAD_BODY_BYTES",
    "BodyGuard",
    "RoutePlan",
    "document_body_limits",
    "role_check_of",
]

#: Largest JSON body by default, bytes (``Settings.max_json_body_bytes``).
DEFAULT_JSON_BODY_BYTES = 1 << 20
#: Largest upload body by default, bytes (``Settings.max_upload_body_bytes``).
DEFAULT_UPLOAD_BODY_BYTES = 64 << 20
#: The OpenAPI schema of the JSON error body (``backend.api.schemas.ErrorOut``).
_ERROR_REF = "#/components/schemas/ErrorOut"
#: Methods that carry no body unless they declare one.
_BODYLESS = frozenset({"GET", "HEAD", "OPTIONS"})


def role_check_of(dependant: Dependant) -> RoleCheck | None:
    """The strongest :class:`RoleCheck` among ``dependant``'s dependencies (None: the
    route needs no sign-in)."""
    found: list[RoleCheck] = []
    stack = list(dependant.dependencies)
    while stack:
        dep = stack.pop()
        if isinstance(dep.call, RoleCheck):
            found.append(dep.call)
        stack.extend(dep.dependencies)
    return max(found, key=lambda c: c.role) if found else None


@dataclass(frozen=True)
class RoutePlan:
    """What the edge does with a body sent to one route."""

    #: Whether FastAPI reads a body for this route (it has body parameters).
    reads_body: bool
    #: Largest body accepted, bytes.
    limit: int
    #: The check run before the body is read (None: no sign-in needed).
    check: RoleCheck | None
    #: ``"upload"`` or ``"json"`` (for the error text).
    kind: str


def _json_answer(
    status: int, code: str, detail: str, headers: dict[str, str] | None
) -> list[Message]:
    body = json.dumps({"error": code, "detail": detail}).encode()
    raw = [
        (b"content-type", b"application/json"),
        (b"content-length", str(len(body)).encode("ascii")),
    ]
    raw += [(k.lower().encode("latin-1"), v.encode("latin-1")) for k, v in (headers or {}).items()]
    return [
        {"type": "http.response.start", "status": status, "headers": raw},
        {"type": "http.response.body", "body": body},
    ]


def _declared_length(scope: Scope) -> tuple[int | None, bool, str | None]:
    """(Content-Length or None, whether Transfer-Encoding is present, error text or None)."""
    length: int | None = None
    chunked = False
    for name, value in scope.get("headers", ()):
        if name == b"content-length":
            text = value.decode("latin-1").strip()
            if not text.isdigit() or len(text) > 18 or (length is not None and int(text) != length):
                return None, chunked, f"Content-Length {text[:40]!r} is not one length in bytes"
            length = int(text)
        elif name == b"transfer-encoding":
            chunked = True
    return length, chunked, None


class _Guarded:
    """The receive and send of one request whose body is counted against ``limit``."""

    def __init__(
        self, receive: Receive, send: Send, *, limit: int, declared: int | None, kind: str
    ) -> None:
        self._receive = receive
        self._send = send
        self.limit = limit
        self.declared = declared
        self.kind = kind
        self.count = 0
        self.started = False
        self.refused = False

    async def receive(self) -> Message:
        if self.refused:
            return {"type": "http.disconnect"}
        message = await self._receive()
        if message["type"] != "http.request":
            return message
        self.count += len(message.get("body", b""))
        if self.count > self.limit:
            await self._refuse(
                413,
                "too_large",
                f"the request body passed {self.limit} bytes; this route accepts at most "
                f"{self.limit} bytes ({self.kind} body)",
            )
            return {"type": "http.disconnect"}
        if self.declared is not None and self.count > self.declared:
            await self._refuse(
                400,
                "bad_request",
                f"the request body is longer than its Content-Length ({self.declared} bytes)",
            )
            return {"type": "http.disconnect"}
        return message

    async def _refuse(self, status: int, code: str, detail: str) -> None:
        if not self.started:  # else the application has answered already: let it finish
            self.refused = True
            for message in _json_answer(status, code, detail, None):
                await self._send(message)

    async def send(self, message: Message) -> None:
        if self.refused:  # the answer to a refused request has been sent
            return
        if message["type"] == "http.response.start":
            self.started = True
        await self._send(message)


class BodyGuard:
    """Pure ASGI middleware of the module docstring.

    Parameters
    ----------
    app : ASGI app
        What follows (the fast path, FastAPI's exception layer and router).
    routes : sequence of routes
        The app's routes (``FastAPI.routes``; read at the first request, when all are in).
    json_limit, upload_limit : int
        Largest JSON and upload body, bytes.
    """

    def __init__(
        self,
        app: ASGIApp,
        *,
        routes: Sequence[BaseRoute],
        json_limit: int = DEFAULT_JSON_BODY_BYTES,
        upload_limit: int = DEFAULT_UPLOAD_BODY_BYTES,
    ) -> None:
        for name, value in (("json_limit", json_limit), ("upload_limit", upload_limit)):
            if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= 1 << 40:
                raise ValueError(f"{name} must be a positive number of bytes, got {value!r}")
        self.app = app
        self.json_limit = json_limit
        self.upload_limit = upload_limit
        self._routes = routes
        self._contexts: list[Any] | None = None
        self._plans: dict[int, RoutePlan] = {}
        self._no_body = RoutePlan(False, json_limit, None, "json")
        #: Requests refused here before their body was read, and while it streamed in.
        self.refused_before_body = 0
        self.refused_while_reading = 0

    # -- routes ------------------------------------------------------------------------
    def _plan_of(self, ctx: Any) -> RoutePlan:
        plan = self._plans.get(id(ctx))
        if plan is None:
            dependant: Dependant | None = getattr(ctx, "dependant", None)
            if dependant is None or not dependant.body_params:
                plan = self._no_body
            else:
                upload = any(isinstance(p.field_info, params.Form) for p in dependant.body_params)
                plan = RoutePlan(
                    True,
                    self.upload_limit if upload else self.json_limit,
                    role_check_of(dependant),
                    "upload" if upload else "JSON",
                )
            self._plans[id(ctx)] = plan
        return plan

    def plan(self, method: str, path: str) -> RoutePlan:
        """What applies to a body sent as ``method path`` (the first route that matches
        both, as the router picks it; no body read when none does)."""
        if self._contexts is None:
            self._contexts = [
                c for c in iter_route_contexts(self._routes)
                if not isinstance(c.original_route, WebSocketRoute)
            ]  # fmt: skip
        for ctx in self._contexts:
            regex = getattr(ctx, "path_regex", None)
            if regex is None or not regex.match(path):
                continue
            methods = getattr(ctx, "methods", None)
            if methods is None:  # a mount (static files): it reads no body
                return self._no_body
            if method in methods:
                return self._plan_of(ctx)
        return self._no_body

    # -- requests ----------------------------------------------------------------------
    async def _answer(
        self, send: Send, status: int, code: str, detail: str, headers: dict[str, str] | None = None
    ) -> None:
        for message in _json_answer(status, code, detail, headers):
            await send(message)

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        declared, chunked, bad = _declared_length(scope)
        if bad is not None:
            self.refused_before_body += 1
            await self._answer(send, 400, "bad_request", bad)
            return
        method = scope["method"]
        if method in _BODYLESS and not chunked and not declared:
            await self.app(scope, receive, send)  # no body: nothing to guard
            return
        path = scope["path"]
        root = scope.get("root_path", "")
        if root and path.startswith(root):
            path = path[len(root) :]
        plan = self.plan(method, path)
        if plan.reads_body:
            if plan.check is not None:
                refusal = await self._check(plan.check, scope)
                if refusal is not None:
                    self.refused_before_body += 1
                    await self._answer(send, *refusal)
                    return
            if declared is not None and declared > plan.limit:
                self.refused_before_body += 1
                await self._answer(
                    send,
                    413,
                    "too_large",
                    f"the request body has {declared} bytes; this route accepts at most "
                    f"{plan.limit} bytes ({plan.kind} body)",
                )
                return
        guard = _Guarded(receive, send, limit=plan.limit, declared=declared, kind=plan.kind)
        await self.app(scope, guard.receive, guard.send)
        if guard.refused:
            self.refused_while_reading += 1

    async def _check(
        self, check: RoleCheck, scope: Scope
    ) -> tuple[int, str, str, dict[str, str] | None] | None:
        """The refusal of ``check`` for this request (None: it passes)."""
        try:
            await check.check_before_body(HTTPConnection(scope))
        except ApiError as exc:
            return exc.status, exc.code, exc.detail, exc.headers
        except VisionCellError as exc:
            return status_of(exc), exc.code, exc.detail, None
        except Exception as exc:
            refusal = database_refusal(exc)
            if refusal is None:
                raise
            return refusal.status, refusal.code, refusal.detail, refusal.headers
        return None


def document_body_limits(routes: Sequence[BaseRoute], *, json_limit: int, upload_limit: int) -> int:
    """Add the 413 answer, with its limit, to the OpenAPI of every route that takes a body
    (call before the schema is first built); returns how many routes were documented."""
    n = 0
    for ctx in iter_route_contexts(routes):
        dependant: Dependant | None = getattr(ctx, "dependant", None)
        if dependant is None or not dependant.body_params:
            continue
        upload = any(isinstance(p.field_info, params.Form) for p in dependant.body_params)
        limit = upload_limit if upload else json_limit
        ctx.responses[413] = {
            # added after the routes were built: the schema by reference (ErrorOut is among
            # the components, every route's other errors use it)
            "content": {"application/json": {"schema": {"$ref": _ERROR_REF}}},
            "description": f"The body has more than {limit} bytes ({'upload' if upload else 'JSON'} "
            "routes' limit), declared or counted as it streams in; refused before it is read",
        }
        n += 1
    return n
