"""Drive an ASGI app with a hand-made request: a body that is counted as it is read, that
may never end, and a client that may disconnect at a chosen moment."""

from __future__ import annotations

import asyncio
import json
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from typing import Any

#: Longest wait for an answer; only bounds a hang (a loaded machine answers in far less).
ANSWER_TIMEOUT_S = 120.0


@dataclass
class Exchange:
    """What the app answered and how much of the body it read."""

    status: int | None = None
    headers: dict[str, str] = field(default_factory=dict)
    body: bytes = b""
    #: Body bytes handed to the app, and ``http.request`` messages it asked for.
    bytes_read: int = 0
    reads: int = 0

    def json(self) -> Any:
        return json.loads(self.body)


def scope_of(method: str, path: str, headers: dict[str, str]) -> dict[str, Any]:
    """An HTTP scope as uvicorn builds it."""
    return {
        "type": "http",
        "asgi": {"version": "3.0", "spec_version": "2.3"},
        "http_version": "1.1",
        "method": method,
        "scheme": "http",
        "path": path,
        "raw_path": path.encode(),
        "query_string": b"",
        "root_path": "",
        "headers": [(k.lower().encode(), v.encode()) for k, v in headers.items()],
        "client": ("127.0.0.1", 50000),
        "server": ("testserver", 80),
    }


async def exchange(
    app: Any,
    method: str,
    path: str,
    *,
    headers: dict[str, str] | None = None,
    chunks: Iterable[bytes] = (),
    disconnect: asyncio.Event | None = None,
) -> Exchange:
    """Send one request to ``app``: its body is ``chunks`` (possibly endless, handed over
    only when the app asks); after the last chunk the client waits for the answer, or
    disconnects when ``disconnect`` is set."""
    out = Exchange()
    it: Iterator[bytes] = iter(chunks)
    pending: bytes | None = next(it, None)
    answered = asyncio.Event()

    async def receive() -> dict[str, Any]:
        nonlocal pending
        if pending is not None:
            chunk, pending = pending, next(it, None)
            out.reads += 1
            out.bytes_read += len(chunk)
            return {"type": "http.request", "body": chunk, "more_body": pending is not None}
        waits = [asyncio.ensure_future(answered.wait())]
        if disconnect is not None:
            waits.append(asyncio.ensure_future(disconnect.wait()))
        try:
            await asyncio.wait(waits, return_when=asyncio.FIRST_COMPLETED)
        finally:
            for w in waits:
                w.cancel()
        return {"type": "http.disconnect"}

    async def send(message: dict[str, Any]) -> None:
        if message["type"] == "http.response.start":
            out.status = message["status"]
            out.headers = {k.decode(): v.decode() for k, v in message.get("headers", [])}
        elif message["type"] == "http.response.body":
            out.body += message.get("body", b"")
            if not message.get("more_body", False):
                answered.set()

    await asyncio.wait_for(
        app(scope_of(method, path, headers or {}), receive, send), ANSWER_TIMEOUT_S
    )
    return out
