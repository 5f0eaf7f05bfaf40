"""The event loop of ``visioncell serve``: uvloop when installed, asyncio otherwise, and
the console WebSocket's per-message deflate off unless asked for."""

from __future__ import annotations

import asyncio
import sys

import pytest
import websockets
from starlette.applications import Starlette
from starlette.routing import WebSocketRoute
from starlette.websockets import WebSocket

from backend.api.limits import uvicorn_options
from backend.eventloop import loop_factory, loop_name, run
from backend.settings import Settings
from tests.utils.servers import run_uvicorn


async def _which() -> str:
    return loop_name(asyncio.get_running_loop())


def test_auto_runs_on_uvloop_when_installed() -> None:
    pytest.importorskip("uvloop")
    assert run(_which()) == "uvloop"
    assert run(_which(), choice="uvloop") == "uvloop"
    assert run(_which(), choice="asyncio") == "asyncio"
    assert loop_factory("asyncio") is None


def test_without_uvloop_auto_falls_back_and_uvloop_is_an_error(monkeypatch) -> None:
    monkeypatch.setitem(sys.modules, "uvloop", None)  # "import uvloop" raises ImportError
    assert loop_factory("auto") is None
    assert run(_which()) == "asyncio"
    with pytest.raises(RuntimeError, match="pip install uvloop"):
        loop_factory("uvloop")


def test_bad_choices_are_refused() -> None:
    with pytest.raises(ValueError, match="'auto', 'uvloop' or 'asyncio'"):
        loop_factory("trio")  # type: ignore[arg-type]
    with pytest.raises(ValueError):
        Settings(event_loop="trio")
    with pytest.raises(TypeError, match="ws_compression"):
        uvicorn_options(ws_compression="no")  # type: ignore[arg-type]
    assert Settings().event_loop == "auto" and Settings().ws_compression is False


async def _echo(ws: WebSocket) -> None:
    await ws.accept()
    await ws.send_text(await ws.receive_text())
    await ws.close()


@pytest.mark.parametrize("compression", [False, True])
def test_websocket_deflate_is_offered_only_when_asked(compression: bool) -> None:
    app = Starlette(routes=[WebSocketRoute("/ws", _echo)])

    async def handshake(base: str) -> str | None:
        url = base.replace("http://", "ws://") + "/ws"
        async with websockets.connect(url) as ws:  # the client offers deflate, as browsers do
            await ws.send("ping")
            assert await ws.recv() == "ping"
            return ws.response.headers.get("Sec-WebSocket-Extensions")

    with run_uvicorn(app, ws_compression=compression) as server:
        ext = asyncio.run(handshake(server.base))
    if compression:
        assert ext is not None and "permessage-deflate" in ext
    else:
        assert ext is None
