"""Live updates for the console over a WebSocket.

The client sends ``{"token": "..."}`` as its first message (browsers cannot set headers on
WebSockets, and tokens in URLs end up in logs).  The server then sends
``{"type": "state", ...}`` at up to ``rate`` Hz and ``{"type": "job", ...}`` when a job
starts or ends.  Close codes: 4401 bad or missing token, 4408 no token within 5 s.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import time

from fastapi import APIRouter, WebSocket, WebSocketDisconnect

from backend.auth import authenticate
from backend.db.models import Role

router = APIRouter(tags=["live"])

_MAX_RATE_HZ = 20.0


@router.websocket("/ws")
async def live(ws: WebSocket) -> None:
    await ws.accept()
    app = ws.app
    settings, db, cell = app.state.settings, app.state.db, app.state.cell
    try:
        async with asyncio.timeout(5.0):
            first = await ws.receive_text()
    except TimeoutError:
        await ws.close(code=4408, reason='send {"token": ...} first')
        return
    except WebSocketDisconnect:
        return
    user_name, role = "anonymous", Role.engineer.name
    if settings.auth_enabled:
        try:
            token = str(json.loads(first).get("token", ""))
        except (ValueError, AttributeError):
            token = ""
        async with db.session() as session:
            user = await authenticate(session, token, settings.secret_key.get_secret_value())
        if user is None:
            await ws.close(code=4401, reason="invalid or revoked token")
            return
        user_name, role = user.name, user.role
    await ws.send_json(
        {"type": "hello", "user": user_name, "role": role, "driver": cell.driver.name}
    )

    jobs: asyncio.Queue[dict] = asyncio.Queue(maxsize=100)

    def on_job(job) -> None:  # type: ignore[no-untyped-def]
        with contextlib.suppress(asyncio.QueueFull):
            jobs.put_nowait(job.public())

    cell.jobs.add_listener(on_job)

    async def send_jobs() -> None:
        while True:
            await ws.send_json({"type": "job", "job": await jobs.get()})

    async def drain_incoming() -> None:
        while True:
            await ws.receive_text()  # the client has nothing else to say; detect closing

    job_task = asyncio.create_task(send_jobs())
    rx_task = asyncio.create_task(drain_incoming())
    try:
        last = 0.0
        async for state in cell.driver.states():
            if rx_task.done() or job_task.done():
                break
            now = time.monotonic()
            if now - last < 1.0 / _MAX_RATE_HZ:
                continue
            last = now
            await ws.send_json({"type": "state", "state": state.as_dict(), "speed": cell.speed})
    except (WebSocketDisconnect, RuntimeError):
        pass
    finally:
        cell.jobs.remove_listener(on_job)
        for t in (job_task, rx_task):
            t.cancel()
            with contextlib.suppress(BaseException):
                await t
