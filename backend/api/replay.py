"""The viser client build served at ``/replay/`` so the console can replay a recorded scene.

The Reports page fetches an inspection's recorded scene (``GET
/api/inspections/{id}/scene``, viser scene-serializer bytes) with the bearer token, makes a
``blob:`` URL of it and opens ``/replay/?playbackPath=<blob URL>`` in a frame: the client
that the installed viser package ships (``viser/client/build/index.html``, one
self-contained file) plays the recording back without a websocket.  Same origin, so the
blob URL is readable; nothing comes from a CDN.  The build starts its scripts inline and
compiles WebAssembly, so this page gets a policy of its own (the console's forbids both);
it still loads nothing from another origin and only this origin may frame it.
"""

from __future__ import annotations

import functools
from pathlib import Path

from fastapi import FastAPI
from fastapi.responses import RedirectResponse, Response

from backend.api.errors import ApiError

__all__ = ["REPLAY_PATH", "install_replay", "replay_policy", "viser_client_index"]

#: Where the replay client is served.
REPLAY_PATH = "/replay/"


def replay_policy() -> str:
    """Content-Security-Policy of the replay page (inline bootstrap, WebAssembly, blob URLs)."""
    return (
        "default-src 'self'; script-src 'self' 'unsafe-inline' 'wasm-unsafe-eval'; "
        "style-src 'self' 'unsafe-inline'; img-src 'self' data: blob:; font-src 'self' data:; "
        "connect-src 'self' blob: data:; worker-src 'self' blob:; object-src 'none'; "
        "base-uri 'self'; form-action 'none'; frame-ancestors 'self'"
    )


@functools.cache
def viser_client_index() -> bytes | None:
    """The installed viser client build (``index.html``), or None when it is missing."""
    try:
        import viser
    except ImportError:  # pragma: no cover - viser is a dependency
        return None
    path = Path(viser.__file__).parent / "client" / "build" / "index.html"
    return path.read_bytes() if path.is_file() else None


def install_replay(app: FastAPI) -> None:
    """Add ``GET /replay/`` (the viser client for scene playback) to ``app``."""

    @app.get(REPLAY_PATH, include_in_schema=False)
    async def replay() -> Response:
        body = viser_client_index()
        if body is None:
            raise ApiError(503, "unavailable", "the viser client build is not installed")
        return Response(
            body,
            media_type="text/html",
            headers={
                "Content-Security-Policy": replay_policy(),
                "Cache-Control": "private, max-age=3600",
            },
        )

    @app.get(REPLAY_PATH.rstrip("/"), include_in_schema=False)
    async def replay_slash() -> RedirectResponse:
        return RedirectResponse(REPLAY_PATH)
