"""The REST E-STOP answered in front of FastAPI.

``POST /api/robot/estop`` with a token known from memory (:func:`backend.api.deps.known_user`)
is pressed and answered by :class:`EStopFastPath`, a pure ASGI layer just in front of
FastAPI's router (inside the security-header, CORS, URL-length and proxy layers, so those
apply unchanged): no routing through every route, no dependency solving, no request body
read.  On a loaded machine that framework work is most of the request's time on the event
loop (``benchmarks/estop.py``), and the stop should not queue behind it.

The answer is the route's own: ``{"state": ...}`` validated by its response model, or the
JSON error of a driver that could not stop the arm.  Anything else falls through to the
FastAPI route unchanged, which gives the same refusals as before: no token, an unknown one
(401, counted by the throttle, or 429 for a blocked address), the cell not running (503),
a query string.
"""

from __future__ import annotations

import json
import logging
from typing import Any

from fastapi.requests import HTTPConnection
from starlette.types import ASGIApp, Receive, Scope, Send

from backend.api.deps import known_user, runtime_of
from backend.api.errors import error_body, status_of
from backend.api.routes.robot import StateOnlyOut
from vision.errors import VisionCellError

__all__ = ["ESTOP_PATH", "EStopFastPath"]

log = logging.getLogger(__name__)

#: The route this layer answers.
ESTOP_PATH = "/api/robot/estop"


def _bearer(scope: Scope) -> str | None:
    for key, value in scope.get("headers", ()):
        if key == b"authorization":
            scheme, _, token = value.decode("latin-1").partition(" ")
            return token.strip() if scheme.lower() == "bearer" and token.strip() else None
    return None


class EStopFastPath:
    """Pure ASGI layer: the E-STOP of a known token pressed and answered at once."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if (
            scope["type"] != "http" or scope["method"] != "POST" or scope["path"] != ESTOP_PATH
            or scope.get("query_string")
        ):  # fmt: skip
            await self.app(scope, receive, send)
            return
        conn = HTTPConnection(scope)
        user = known_user(conn, _bearer(scope))
        rt = runtime_of(conn.app)
        if user is None or rt is None or not rt.running:
            await self.app(scope, receive, send)  # FastAPI answers the refusal
            return
        status, body = 200, None
        try:
            await rt.cell.estop(by=user.name, role=user.role, source="rest")
        except VisionCellError as exc:
            status, body = status_of(exc), error_body(exc.code, exc.detail)
        except Exception as exc:
            log.error("internal error in the E-STOP: %r", exc, exc_info=exc)
            status = 500
            body = error_body(
                "internal_error",
                f"internal error ({type(exc).__name__}); it was logged on the server",
            )
        if body is None:
            content: Any = StateOnlyOut.model_validate(
                {"state": rt.cell.driver.state.as_dict()}
            ).model_dump(mode="json")
        else:
            content = body
        raw = json.dumps(content, separators=(",", ":")).encode()
        await send(
            {
                "type": "http.response.start",
                "status": status,
                "headers": [
                    (b"content-type", b"application/json"),
                    (b"content-length", str(len(raw)).encode("ascii")),
                ],
            }
        )
        await send({"type": "http.response.body", "body": raw})
