"""A raw viser client for tests: the real websocket protocol, without a browser.

It opens the websocket exactly as viser's page does (subprotocol ``viser-v<version>``),
reads and discards what the server sends, and sends the same ``GuiUpdateMessage`` a
browser sends when a button is clicked or a field edited.  It can send messages for any
uuid, which is how a hostile client would try to press buttons it was never shown.
"""

from __future__ import annotations

import asyncio
import contextlib
from typing import Any

import msgspec
import viser
import websockets


class RawViserClient:
    """One websocket connection to a viser server."""

    def __init__(self, port: int, *, path: str = "/") -> None:
        self.url = f"ws://127.0.0.1:{port}{path}"
        self._ws: Any = None
        self._drain: asyncio.Task[None] | None = None
        self.received_bytes = 0

    async def __aenter__(self) -> RawViserClient:
        self._ws = await websockets.connect(
            self.url, subprotocols=[f"viser-v{viser.__version__}"], max_size=None
        )
        self._drain = asyncio.create_task(self._read())
        # viser counts a client as connected once it has reported its camera.
        await self._send(
            {
                "type": "ViewerCameraMessage",
                "wxyz": (1.0, 0.0, 0.0, 0.0),
                "position": (2.0, -2.0, 1.5),
                "fov": 1.0,
                "near": 0.01,
                "far": 100.0,
                "image_height": 480,
                "image_width": 640,
                "look_at": (0.0, 0.0, 0.5),
                "up_direction": (0.0, 0.0, 1.0),
            }
        )
        return self

    async def __aexit__(self, *exc: object) -> None:
        if self._drain is not None:
            self._drain.cancel()
            with contextlib.suppress(BaseException):
                await self._drain
        await self._ws.close()

    async def _read(self) -> None:
        async for message in self._ws:
            self.received_bytes += len(message)

    async def update(self, uuid: str, **updates: Any) -> None:
        """Send a GUI update for ``uuid`` (what the page sends on an edit)."""
        await self._send({"type": "GuiUpdateMessage", "uuid": uuid, "updates": updates})

    async def _send(self, message: dict[str, Any]) -> None:
        await self._ws.send(msgspec.msgpack.encode(message))

    async def press(self, uuid: str) -> None:
        """Click the button ``uuid`` (what the page sends on a click)."""
        await self.update(uuid, value=True)


def uuid_of(handle: Any) -> str:
    """The wire id of a viser GUI handle."""
    return handle._impl.uuid
