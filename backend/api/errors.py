"""Map every error to ``{"error": code, "detail": text}`` with the right status.

The status comes from the exception's class, never from its message: domain errors
(:class:`vision.errors.VisionCellError` and subclasses such as ``NotFound``, ``Conflict``,
``InvalidInput``) carry ``code`` and ``http_status``; :class:`ApiError` carries them for
the HTTP layer's own refusals (401, 403, 503).  Anything else, including a bare
``ValueError``, is a bug: a 500 with a log line and the same JSON body.
"""

from __future__ import annotations

import logging

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException

from vision.errors import VisionCellError

__all__ = ["ApiError", "error_body", "install_error_handlers"]

log = logging.getLogger(__name__)

_HTTP_CODES = {
    400: "bad_request",
    401: "unauthorized",
    403: "forbidden",
    404: "not_found",
    405: "method_not_allowed",
    409: "conflict",
    413: "too_large",
    414: "uri_too_long",
    415: "unsupported_media_type",
    422: "validation_error",
    503: "unavailable",
}


class ApiError(Exception):
    """An error raised by a handler or a dependency, with a stable code."""

    def __init__(
        self, status: int, code: str, detail: str, *, headers: dict[str, str] | None = None
    ) -> None:
        super().__init__(detail)
        self.status = status
        self.code = code
        self.detail = detail
        self.headers = headers


def error_body(code: str, detail: str) -> dict[str, str]:
    """The JSON body of every error answer."""
    return {"error": code, "detail": detail}


def _loc(loc: tuple[object, ...]) -> str:
    # The first element says where the value came from (body, query, path, header).
    parts = (
        [str(p) for p in loc[1:]]
        if loc and loc[0] in ("body", "query", "path", "header", "cookie")
        else [str(p) for p in loc]
    )
    return ".".join(parts) or "request"


def _given(err: dict) -> str:
    if "input" not in err or err.get("type") in ("missing", "json_invalid"):
        return ""
    text = repr(err["input"])
    return f" (got {text[:80]}{'...' if len(text) > 80 else ''})"


def _internal(request: Request, exc: Exception) -> JSONResponse:
    log.error(
        "internal error in %s %s: %s: %s",
        request.method,
        request.url.path,
        type(exc).__name__,
        exc,
        exc_info=exc,
    )
    return JSONResponse(
        error_body(
            "internal_error",
            f"internal error ({type(exc).__name__}); it was logged on the server",
        ),
        status_code=500,
    )


def install_error_handlers(app: FastAPI) -> None:
    """Register the handlers on ``app``."""

    @app.exception_handler(ApiError)
    async def _api_error(_: Request, exc: ApiError) -> JSONResponse:
        return JSONResponse(
            error_body(exc.code, exc.detail), status_code=exc.status, headers=exc.headers
        )

    @app.exception_handler(VisionCellError)
    async def _domain_error(_: Request, exc: VisionCellError) -> JSONResponse:
        return JSONResponse(error_body(exc.code, exc.detail), status_code=exc.http_status)

    @app.exception_handler(RequestValidationError)
    async def _validation(_: Request, exc: RequestValidationError) -> JSONResponse:
        msgs = []
        for err in exc.errors():
            msg = str(err.get("msg", "invalid")).removeprefix("Value error, ")
            loc = tuple(err.get("loc", ()))
            if len(loc) <= 1 and err.get("type") == "value_error":
                msgs.append(msg)  # a check across fields of the whole body
            else:
                msgs.append(f"{_loc(loc)}: {msg}{_given(err)}")
        return JSONResponse(error_body("validation_error", "; ".join(msgs)), status_code=422)

    @app.exception_handler(StarletteHTTPException)
    async def _http(_: Request, exc: StarletteHTTPException) -> JSONResponse:
        code = _HTTP_CODES.get(exc.status_code, "error")
        return JSONResponse(
            error_body(code, str(exc.detail)), status_code=exc.status_code, headers=exc.headers
        )

    # A ValueError (or any other exception) that reached the edge is a bug: the input
    # should have been refused by a schema or a domain error.  Registered for ValueError
    # explicitly so that it is answered here (the catch-all Exception handler answers too,
    # but Starlette re-raises to the server afterwards).
    @app.exception_handler(ValueError)
    async def _value(request: Request, exc: ValueError) -> JSONResponse:
        return _internal(request, exc)

    @app.exception_handler(Exception)
    async def _any(request: Request, exc: Exception) -> JSONResponse:
        return _internal(request, exc)
