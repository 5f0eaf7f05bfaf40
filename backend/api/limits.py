"""Limits on the HTTP layer, answered with the JSON error body like every other error.

Two places can refuse a request before FastAPI sees it:

* the HTTP parser of uvicorn, for a request it cannot parse (a malformed request head, or
  one longer than :data:`MAX_REQUEST_HEAD_BYTES`).  Uvicorn answers those with a
  ``text/plain`` 400 of its own; :class:`JsonErrorHttpProtocol` (uvicorn's h11 protocol
  with that one answer replaced) sends ``{"error": "bad_request", "detail": ...}``;
* :class:`UrlLengthLimit`, a pure ASGI middleware, refuses a path plus query string longer
  than :data:`MAX_URL_BYTES` with a JSON 414 before any routing or parsing of parameters.

The h11 parser is used (not httptools, whose fixed limit of about 80 KB on a request line
cannot be raised): its limit on an incomplete request head is raised to
:data:`MAX_REQUEST_HEAD_BYTES`, so every URL between 8 KB and 1 MiB reaches the middleware
and gets the 414, and anything longer still gets a JSON 400 rather than plain text.

:func:`uvicorn_options` gives the options ``visioncell serve`` (and the tests) pass to
uvicorn, so a real server behaves as the tests check.
"""

from __future__ import annotations

import json
from typing import Any

import h11
from starlette.types import ASGIApp, Receive, Scope, Send
from uvicorn.protocols.http.h11_impl import H11Protocol

__all__ = [
    "MAX_REQUEST_HEAD_BYTES",
    "MAX_URL_BYTES",
    "JsonErrorHttpProtocol",
    "UrlLengthLimit",
    "uvicorn_options",
]

#: Longest path plus query string accepted, bytes (the usual limit of proxies and browsers).
MAX_URL_BYTES = 8192
#: Longest request head (request line and headers) the parser buffers, bytes.
MAX_REQUEST_HEAD_BYTES = 1 << 20


def _json_error(status: int, code: str, detail: str) -> tuple[bytes, list[tuple[bytes, bytes]]]:
    body = json.dumps({"error": code, "detail": detail}).encode()
    headers = [
        (b"content-type", b"application/json"),
        (b"content-length", str(len(body)).encode("ascii")),
    ]
    return body, headers


class UrlLengthLimit:
    """Pure ASGI middleware: a 414 JSON answer for a URL over ``max_bytes``.

    Parameters
    ----------
    app : ASGI app
        The application behind the limit.
    max_bytes : int
        Longest ``path + "?" + query`` in bytes, as sent (percent-encoded).
    """

    def __init__(self, app: ASGIApp, *, max_bytes: int = MAX_URL_BYTES) -> None:
        if max_bytes < 256:
            raise ValueError(f"max_bytes must be at least 256, got {max_bytes!r}")
        self.app = app
        self.max_bytes = max_bytes

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        raw = scope.get("raw_path") or scope.get("path", "").encode("utf-8", "surrogateescape")
        n = len(raw) + len(scope.get("query_string", b""))
        if n <= self.max_bytes:
            await self.app(scope, receive, send)
            return
        if scope["type"] == "websocket":
            await send({"type": "websocket.close", "code": 1009})
            return
        body, headers = _json_error(
            414, "uri_too_long", f"the URL has {n} bytes; at most {self.max_bytes} are accepted"
        )
        await send({"type": "http.response.start", "status": 414, "headers": headers})
        await send({"type": "http.response.body", "body": body})


#: After a parse-error answer, how long and how much of the rest of the request is read and
#: dropped before the connection closes (a "lingering close"): closing a socket with unread
#: data makes the kernel send a reset, which can destroy the answer before the client reads it.
LINGER_S = 2.0
LINGER_BYTES = 16 << 20
#: The same bound after an answer given before the request's body was read (a refusal by
#: the edge, :mod:`backend.api.edge`): as much as the largest upload, so a client that
#: sends its whole body before reading still gets the answer, within ``LINGER_S``.
REFUSED_LINGER_BYTES = 64 << 20


class JsonErrorHttpProtocol(H11Protocol):
    """Uvicorn's h11 protocol whose parse-error answer is the JSON error body, followed by a
    bounded lingering close (:data:`LINGER_S`, :data:`LINGER_BYTES`); an answer sent before
    the request's body was read ends the same way (:data:`REFUSED_LINGER_BYTES`), its
    unread body dropped unparsed."""

    _lingering = False
    _dropped = 0
    _linger_limit = LINGER_BYTES
    _linger_timer: Any = None

    def data_received(self, data: bytes) -> None:
        if self._lingering:
            self._dropped += len(data)
            if self._dropped > self._linger_limit:
                self._end_linger()
            return
        super().data_received(data)

    def eof_received(self) -> None:
        if self._lingering:  # the client has sent everything: nothing left to drop
            self._end_linger()
            return
        super().eof_received()

    def connection_lost(self, exc: Exception | None) -> None:
        if self._linger_timer is not None:
            self._linger_timer.cancel()
            self._linger_timer = None
        super().connection_lost(exc)

    def _end_linger(self) -> None:
        self._lingering = False
        if self._linger_timer is not None:
            self._linger_timer.cancel()
            self._linger_timer = None
        self.transport.close()

    def on_response_complete(self) -> None:
        if self.conn.their_state is h11.SEND_BODY and not self.transport.is_closing():
            # Answered before the body was read (the edge refused it, or a 404): the rest
            # is dropped without parsing it, and the connection closes after a bounded
            # linger instead of h11 reading every remaining byte on the event loop.
            self.server_state.total_requests += 1
            self._start_linger(REFUSED_LINGER_BYTES)
            self.flow.resume_reading()
            return
        super().on_response_complete()

    def _start_linger(self, limit: int) -> None:
        """Half-close (the answer and a FIN are out) and drop what the client still sends
        until it stops, ``limit`` bytes have come, or :data:`LINGER_S` have passed."""
        if not self.transport.can_write_eof():
            self.transport.close()
            return
        self.transport.write_eof()
        self._lingering = True
        self._linger_limit = limit
        self._linger_timer = self.loop.call_later(LINGER_S, self._end_linger)

    def send_400_response(self, msg: str) -> None:
        body, headers = _json_error(
            400,
            "bad_request",
            f"{msg.rstrip('.')}: the request line or headers are malformed or too long "
            f"(URLs up to {MAX_URL_BYTES} bytes, request heads up to "
            f"{MAX_REQUEST_HEAD_BYTES} bytes are accepted)",
        )
        content = [b"HTTP/1.1 400 Bad Request\r\n"]
        for name, value in [*self.server_state.default_headers, *headers]:
            content.extend([name, b": ", value, b"\r\n"])
        content.extend([b"connection: close\r\n", b"\r\n", body])
        self.transport.write(b"".join(content))
        self._start_linger(LINGER_BYTES)


def uvicorn_options(*, ws_compression: bool = False) -> dict[str, Any]:
    """Keyword arguments for ``uvicorn.run`` / ``uvicorn.Config`` that give JSON errors and
    leave proxy headers to the app;
    ``ws_compression`` offers per-message deflate on WebSockets (``Settings.ws_compression``)."""
    if not isinstance(ws_compression, bool):
        raise TypeError(f"ws_compression must be a bool, got {ws_compression!r}")
    return {
        # X-Forwarded-For is believed only from VISIONCELL_TRUSTED_PROXIES, by the app
        # (backend.api.proxies); uvicorn's own handling would trust any loopback peer.
        "proxy_headers": False,
        "http": JsonErrorHttpProtocol,
        "h11_max_incomplete_event_size": MAX_REQUEST_HEAD_BYTES,
        "ws_per_message_deflate": ws_compression,
    }
