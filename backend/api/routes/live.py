"""Live updates for the console over a WebSocket (``/api/ws``), fed by the cell's event bus.

The client sends ``{"token": "..."}`` as its first message, a text frame (browsers cannot set
headers on WebSockets, and tokens in URLs end up in logs).  Close codes: 1003 a binary first
frame, 4401 bad or missing token,
4408 no token within 5 s, 1013 the cell is not running, 4429 too many failed sign-ins from
this address (the reason says when to retry).  A bad token counts against the client's
address like a REST sign-in; the token is checked again every :data:`RECHECK_S` seconds
and the socket is closed with 4401 once it expires or is revoked.

Messages from the server (JSON objects, ``type`` first):

- ``{"type": "hello", "user", "role", "driver"}`` once, after the token is accepted;
  then at once one ``state`` and one ``camera`` message with the current values.
- ``{"type": "state", "state": RobotState.as_dict(), "speed": float}``: the arm, at up to
  20 Hz, and at once when ``connected``, ``estopped`` or ``fault`` change.
- ``{"type": "job", "job": Job.public()}``: a job started, reported progress or ended.  Start
  and end are always sent; progress reports are throttled to at most
  :data:`JOB_PROGRESS_HZ` per job, the latest one being sent when the interval is over (a
  console can follow jobs from these messages alone, without polling ``/api/jobs``).
- ``{"type": "camera", "camera": {"name", "ok", "frames", "fps", "error", "retries"}}``: the
  camera's health changed.
- ``{"type": "inspection", "inspection": {...}}``: an inspection ended (id, decision, model,
  reason, score, viewpoints, T_base_obj, the cameras of the views, pick);
- ``{"type": "estop", "active": bool, "conveyors": [names], "arm_latched": bool, "by": name,
  "source": where}``: the cell-wide emergency stop was pressed or reset (``source``:
  ``rest``, ``ws``, ``view3d``, ``cell``).

Messages from the client after its token: ``{"type": "estop"}`` presses the emergency stop
at once (any signed-in role; its answer is the ``estop`` message every socket gets); other
messages are ignored.  A socket stays open through a database outage (its token cannot be
revoked meanwhile), and a token this cell saw valid within the hour may open one then.

Every message but ``hello`` also carries ``"at"``: when its event was made, wall-clock
seconds since the epoch (``benchmarks/load.py`` measures the message lag with it).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import time
from collections.abc import Callable
from typing import Any

from fastapi import APIRouter, WebSocket, WebSocketDisconnect

from backend.api.deps import client_address, get_runtime, get_settings, signed_in
from backend.api.errors import ApiError
from backend.auth import hash_token, token_is_live, well_formed
from backend.cell.events import (
    ArmState,
    CameraStatus,
    CellEvent,
    CellStopped,
    InspectionDone,
    JobProgress,
    JobState,
)
from backend.db.models import Role, User
from backend.inspection.recovery import is_database_error
from backend.throttle import TooManyAttempts

router = APIRouter(tags=["live"])

#: Largest rate of ``job`` messages from progress reports, per job, Hz.
JOB_PROGRESS_HZ = 4.0
#: How often an open socket's token is checked again (expiry, revocation), seconds.
RECHECK_S = 5.0
#: Longest message a client may send after its token, characters (longer ones are ignored).
MAX_CLIENT_MESSAGE = 1024

log = logging.getLogger(__name__)


def asks_estop(text: str) -> bool:
    """Whether a client's message is ``{"type": "estop"}`` (at most
    :data:`MAX_CLIENT_MESSAGE` characters; anything else is ignored)."""
    if not isinstance(text, str) or len(text) > MAX_CLIENT_MESSAGE:
        return False
    try:
        msg = json.loads(text)
    except ValueError:
        return False
    return isinstance(msg, dict) and msg.get("type") == "estop"


def _message(event: Any) -> dict[str, Any] | None:
    msg = _body(event)
    if msg is not None:
        # When the event was made, wall-clock seconds (clients measure the lag with it).
        msg["at"] = time.time() - (time.monotonic() - event.stamp_s)
    return msg


def _cell_stopped(event: CellStopped) -> dict[str, Any]:
    return {"type": "estop", "active": event.active, "conveyors": list(event.conveyors),
            "arm_latched": event.arm_latched, "by": event.by, "source": event.source}  # fmt: skip


#: The message of each event type a client is sent (others are not sent).
MESSAGES: dict[type[CellEvent], Callable[[Any], dict[str, Any]]] = {
    ArmState: lambda e: {"type": "state", "state": e.state.as_dict(), "speed": e.speed},
    JobState: lambda e: {"type": "job", "job": e.job},
    JobProgress: lambda e: {"type": "job", "job": e.job},
    CameraStatus: lambda e: {"type": "camera", "camera": e.as_dict()},
    CellStopped: _cell_stopped,
    InspectionDone: lambda e: {"type": "inspection", "inspection": e.as_dict()},
}


def _body(event: Any) -> dict[str, Any] | None:
    make = MESSAGES.get(type(event))
    return None if make is None else make(event)


@router.websocket("/ws")
async def live(ws: WebSocket) -> None:
    await ws.accept()
    try:
        rt = get_runtime(ws)
    except ApiError:
        await ws.close(code=1013, reason="the cell is not running")
        return
    settings, cell = get_settings(ws), rt.cell
    try:
        async with asyncio.timeout(5.0):
            message = await ws.receive()
    except TimeoutError:
        await ws.close(code=4408, reason='send {"token": ...} first')
        return
    except WebSocketDisconnect:
        return
    if message.get("type") == "websocket.disconnect":
        return
    first = message.get("text")
    if not isinstance(first, str):  # a binary frame: this socket speaks JSON text only
        await ws.close(code=1003, reason='send {"token": ...} as a text frame')
        return
    user_name, role = "anonymous", Role.engineer.name
    secret = settings.secret_key.get_secret_value()
    token = ""
    if settings.auth_enabled:
        client = client_address(ws)
        try:
            rt.signin_throttle.check(client)
        except TooManyAttempts as exc:
            await ws.close(code=4429, reason=str(exc))
            return
        try:
            token = str(json.loads(first).get("token", ""))
        except (ValueError, AttributeError):
            token = ""
        try:
            user = await signed_in(ws, token)
        except Exception as exc:
            if not is_database_error(exc):
                raise
            # The database is unavailable: a token this cell saw valid within the hour
            # still gets its live view (and its E-STOP); any other must try again later.
            known = rt.known_tokens.get(hash_token(token, secret)) if well_formed(token) else None
            if known is None:
                await ws.close(code=1013, reason="the database is unavailable: try again later")
                return
            user = User(id=known.user_id, name=known.user, role=known.role)
        if user is None:
            rt.signin_throttle.failure(client)
            await ws.close(code=4401, reason="invalid, expired or revoked token")
            return
        user_name, role = user.name, user.role

    sub = cell.bus.subscribe(
        ArmState, JobState, JobProgress, CameraStatus, CellStopped, InspectionDone
    )

    async def drain_incoming() -> None:
        # The client says only E-STOP (a text frame); anything else, binary frames included,
        # is ignored. This also notices the socket closing.
        while True:
            msg = await ws.receive()
            if msg.get("type") == "websocket.disconnect":
                return
            text = msg.get("text")
            if text is not None and asks_estop(text):  # at once: the send loop may wait
                try:
                    await cell.estop(by=user_name, role=role, source="ws")
                except Exception as exc:  # the estop message says the arm was not latched
                    log.error("E-STOP from the WebSocket of %s: %r", user_name, exc)

    rx_task = asyncio.create_task(drain_incoming())
    try:
        await ws.send_json(
            {
                "type": "hello",
                "user": user_name,
                "role": role,
                "driver": cell.driver.name,
            }
        )
        await ws.send_json(_message(ArmState(state=cell.driver.state, speed=cell.speed)))
        await ws.send_json(_message(cell.camera_status()))
        period = 1.0 / JOB_PROGRESS_HZ
        last_sent: dict[str, float] = {}  # job id -> time of its last progress message
        pending: dict[str, JobProgress] = {}  # job id -> newest progress not sent yet
        checked_at = time.monotonic()
        while not rx_task.done():
            now = time.monotonic()
            if settings.auth_enabled and now - checked_at >= RECHECK_S:
                checked_at = now
                try:
                    async with rt.database.session() as session:
                        live = await token_is_live(session, token, secret)
                except Exception as exc:
                    if not is_database_error(exc):
                        raise
                    live = True  # no revocation commits while the database is down either
                if not live:
                    await ws.close(code=4401, reason="the token expired or was revoked")
                    break
            due = [jid for jid, ev in pending.items() if now - last_sent.get(jid, 0.0) >= period]
            for jid in due:
                last_sent[jid] = now
                await ws.send_json(_message(pending.pop(jid)))
            wait = 1.0
            if pending:
                wait = min(period - (now - last_sent.get(j, 0.0)) for j in pending)
            get = asyncio.ensure_future(sub.get(timeout_s=max(0.0, min(wait, 1.0))))
            await asyncio.wait({get, rx_task}, return_when=asyncio.FIRST_COMPLETED)
            if not get.done():  # the client went away (or the server is closing it)
                get.cancel()
                break
            event = get.result()
            if event is None:
                continue
            if isinstance(event, JobProgress):
                if time.monotonic() - last_sent.get(event.job_id, 0.0) < period:
                    pending[event.job_id] = event
                    continue
                last_sent[event.job_id] = time.monotonic()
            elif isinstance(event, JobState):
                pending.pop(event.job_id, None)  # the state message carries the newest progress
                if event.state != "running":
                    last_sent.pop(event.job_id, None)
            msg = _message(event)
            if msg is not None:
                await ws.send_json(msg)
    except (WebSocketDisconnect, RuntimeError):
        pass
    finally:
        sub.close()
        rx_task.cancel()
        with contextlib.suppress(BaseException):
            await rx_task
