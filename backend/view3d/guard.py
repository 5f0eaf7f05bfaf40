"""Keep what a 3D view client sends from filling the log.

viser hands each websocket message to its handlers in a task of its own, and a handler
that fails on a message (a GUI update naming a property the element does not have, a value
of the wrong type) leaves an exception nobody retrieves: asyncio logs it with a traceback,
once per message, so any client, signed in or not, could fill the log.  A frame viser
cannot decode (not msgpack, an unknown message type, a text frame) ends that client's
connection with another traceback from the websocket server.

:class:`MessageGuard` wraps viser's message dispatch (the server's and each client's) so
that a message whose handler fails is dropped and said once per client, on one line
without a traceback; the connection stays open.  A connection that ends on a frame viser
cannot decode (its decoder is bound when the server starts, out of reach) is logged on one
clean line by :class:`HandlerFailures`: once per connection, that is once per client.
Both reach into viser internals (``_websock_server``, ``_websock_connection``), as
:mod:`backend.view3d.server` does for a client's request path; if those change, the guard
is skipped and says so once.
"""

from __future__ import annotations

import logging
from collections.abc import Awaitable, Callable
from typing import Any

__all__ = ["HandlerFailures", "MessageGuard"]

log = logging.getLogger(__name__)

#: Most clients remembered as already logged (ids of clients that left are forgotten).
MAX_LOGGED_CLIENTS = 4096


def _short(exc: BaseException) -> str:
    text = f"{type(exc).__name__}: {exc}"
    return text if len(text) <= 160 else text[:157] + "..."


class MessageGuard:
    """Drops the messages a 3D view client sends that viser's handlers fail on, logging
    once per client."""

    def __init__(self) -> None:
        self._logged: set[int] = set()
        self.installed = False

    def install(self, server: Any) -> None:
        """Wrap the server-wide dispatch of the viser ``server``."""
        ws: Any = getattr(server, "_websock_server", None)
        handle = getattr(ws, "_handle_incoming_message", None)
        if handle is None:
            log.warning("3D view: viser's message dispatch was not found; client messages "
                        "that fail are logged by viser itself")  # fmt: skip
            return
        ws._handle_incoming_message = self._wrap(handle)
        ws_log = logging.getLogger("websockets.server")
        if not any(isinstance(f, HandlerFailures) for f in ws_log.filters):
            ws_log.addFilter(HandlerFailures())
        self.installed = True

    def attach(self, client: Any) -> None:
        """Wrap the dispatch of one client's own GUI elements (its panel)."""
        conn: Any = getattr(client, "_websock_connection", None)
        handle = getattr(conn, "_handle_incoming_message", None)
        if self.installed and handle is not None:
            conn._handle_incoming_message = self._wrap(handle)

    def forget(self, client_id: int) -> None:
        """The client left."""
        self._logged.discard(client_id)

    def _wrap(
        self, handle: Callable[[int, Any], Awaitable[None]]
    ) -> Callable[[int, Any], Awaitable[None]]:
        async def guarded(client_id: int, message: Any) -> None:
            try:
                await handle(client_id, message)
            except Exception as exc:
                self._once(client_id, f"a {type(message).__name__} that failed ({_short(exc)})")

        return guarded

    def _once(self, client_id: int, what: str) -> None:
        if client_id in self._logged:
            return
        if len(self._logged) >= MAX_LOGGED_CLIENTS:
            self._logged.clear()
        self._logged.add(client_id)
        log.warning("3D view client %s sent %s; dropped (further ones from it quietly)",
                    client_id, what)  # fmt: skip


class HandlerFailures(logging.Filter):
    """Turns the websocket server's "connection handler failed" traceback into one line."""

    def filter(self, record: logging.LogRecord) -> bool:
        if record.getMessage() == "connection handler failed" and record.exc_info:
            exc = record.exc_info[1]
            record.msg = "3D view: a client's connection ended on %s"
            record.args = (_short(exc) if exc is not None else "an error",)
            record.exc_info = None
            record.exc_text = None
            record.levelno, record.levelname = logging.WARNING, "WARNING"
        return True
