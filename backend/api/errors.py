"""Map every error to ``{"error": code, "detail": text}`` with the right status.

The status comes from the exception's class, never from its message: domain errors
(:class:`vision.errors.VisionCellError` and subclasses such as ``NotFound``, ``Conflict``,
``InvalidInput``) carry a ``code`` and stay free of HTTP; :data:`STATUS_OF_ERROR` is the
one table from their classes to HTTP statuses (:func:`status_of`: a class not listed takes
its nearest listed base's).  :class:`ApiError` carries code and status for the HTTP layer's
own refusals (401, 403, 503).  A database that cannot serve the request
now is a 503 with ``Retry-After`` (:func:`database_refusal`): every pooled connection busy
(SQLAlchemy's pool ``TimeoutError``, :class:`~backend.db.session.DatabaseBusy`), or the
server away (PEP 249 ``OperationalError`` / ``InterfaceError``: refused or lost connection,
a locked SQLite file; a connection SQLAlchemy saw invalidated).  Anything else, including a
bare ``ValueError``, is a bug: a 500 with a log line and the same JSON body.
"""

from __future__ import annotations

import logging
import time

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from sqlalchemy import exc as sa_exc
from starlette.exceptions import HTTPException as StarletteHTTPException

from backend.calibration.sessions import OtherCell
from backend.cell.errors import MoveAborted, PathBlocked
from backend.db.session import DatabaseBusy
from backend.heavy import Busy, ClientGone, PixelBudgetExceeded
from backend.inspection.errors import CarriedAway, NoObject
from backend.recognition.images import ImageTooLarge, UnsupportedImage
from backend.recognition.index import StaleFeatures
from backend.recognition.segment import SegmentationFailed
from backend.recognition.teach import TeachTimeout
from backend.recognition.views import TooFewFeatures
from robot.errors import (
    DriverError,
    JointLimitError,
    RobotBusy,
    RobotError,
    SimError,
    TrajectoryTooLong,
    Unreachable,
)
from vision.errors import (
    CalibrationError,
    CameraError,
    Conflict,
    ImageError,
    InvalidInput,
    NotFound,
    RecognitionFailed,
    StreamEnded,
    VisionCellError,
)
from vision.pose import PoseFailed
from vision.recognition.light import LightChanged
from vision.recognition.serial import IndexFormatError

__all__ = [
    "BUSY_RETRY_S",
    "DOWN_RETRY_S",
    "STATUS_OF_ERROR",
    "ApiError",
    "database_refusal",
    "error_body",
    "install_error_handlers",
    "status_of",
]

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


#: The HTTP status of each domain error class.  A class not listed answers with the status
#: of its nearest listed base in its method resolution order (``NothingTrained`` with
#: ``Conflict``'s 409), so a new error needs a row only when its status differs.
STATUS_OF_ERROR: dict[type[VisionCellError], int] = {
    VisionCellError: 400,
    # the request's values or files
    InvalidInput: 422,
    TooFewFeatures: 422,
    ImageError: 422,
    IndexFormatError: 422,
    ImageTooLarge: 413,
    PixelBudgetExceeded: 413,
    UnsupportedImage: 415,
    NotFound: 404,
    # the work could not be done with what was given
    CalibrationError: 422,
    RecognitionFailed: 422,
    SegmentationFailed: 422,
    PoseFailed: 422,
    Unreachable: 422,
    JointLimitError: 422,
    TrajectoryTooLong: 422,
    PathBlocked: 422,
    # the cell's state does not allow it now
    Conflict: 409,
    OtherCell: 409,
    RobotError: 409,
    RobotBusy: 409,
    MoveAborted: 409,
    SimError: 409,
    StreamEnded: 409,
    LightChanged: 409,
    StaleFeatures: 409,
    TeachTimeout: 409,
    CarriedAway: 409,
    NoObject: 409,
    # a device or the server cannot serve it now
    CameraError: 503,
    DriverError: 503,
    Busy: 503,
    # nobody is left to read the answer (nginx's code)
    ClientGone: 499,
}


def status_of(error: VisionCellError | type[VisionCellError]) -> int:
    """The HTTP status a domain error (an instance or a class) is answered with: that of
    the first class of its method resolution order listed in :data:`STATUS_OF_ERROR`."""
    cls = error if isinstance(error, type) else type(error)
    for base in cls.__mro__:
        status = STATUS_OF_ERROR.get(base)
        if status is not None:
            return status
    raise TypeError(f"{cls.__qualname__} is not a VisionCellError")


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


#: ``Retry-After`` of a 503 when every connection was busy (a surge passes in seconds), s.
BUSY_RETRY_S = 2
#: ``Retry-After`` of a 503 when the database is away (a restart, a failover), s.
DOWN_RETRY_S = 5
#: Least time between two log lines about the database refusing requests, s.
_LOG_EVERY_S = 10.0
_last_log = [float("-inf")]


def database_refusal(exc: BaseException) -> ApiError | None:
    """The 503 answer to a database that cannot serve a request now, or None when ``exc``
    is not such an error (a bug, answered 500).

    The class decides, never the message: the pool's wait ran out (``TimeoutError`` of
    SQLAlchemy, :class:`DatabaseBusy`), or the DB-API driver raised ``OperationalError``
    or ``InterfaceError`` (PEP 249: errors of the database's operation, not of the
    program), or SQLAlchemy found the connection invalidated (a disconnect).
    """
    if isinstance(exc, sa_exc.TimeoutError | DatabaseBusy):
        return ApiError(
            503,
            "database_busy",
            f"every database connection is busy ({exc}); try again shortly",
            headers={"Retry-After": str(BUSY_RETRY_S)},
        )
    if isinstance(exc, sa_exc.OperationalError | sa_exc.InterfaceError) or (
        isinstance(exc, sa_exc.DBAPIError) and exc.connection_invalidated
    ):
        orig = getattr(exc, "orig", None) or exc
        return ApiError(
            503,
            "database_unavailable",
            f"the database is unavailable ({type(orig).__name__}); try again shortly",
            headers={"Retry-After": str(DOWN_RETRY_S)},
        )
    return None


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
        return JSONResponse(error_body(exc.code, exc.detail), status_code=status_of(exc))

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

    async def _database(request: Request, exc: Exception) -> JSONResponse:
        refusal = database_refusal(exc)
        if refusal is None:
            return _internal(request, exc)
        now = time.monotonic()
        if now - _last_log[0] >= _LOG_EVERY_S:  # once per outage, not once per request
            _last_log[0] = now
            log.warning(
                "database refused %s %s (503): %s: %s",
                request.method, request.url.path, type(exc).__name__, str(exc)[:300],
            )  # fmt: skip
        return JSONResponse(
            error_body(refusal.code, refusal.detail), status_code=503, headers=refusal.headers
        )

    # Registered per class so that Starlette's exception middleware answers them (the
    # catch-all below is the server-error middleware's, which re-raises afterwards).
    for cls in (sa_exc.TimeoutError, DatabaseBusy, sa_exc.DBAPIError):
        app.add_exception_handler(cls, _database)

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
