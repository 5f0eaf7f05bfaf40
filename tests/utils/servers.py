"""A real uvicorn server in a thread, on a free port, with the options ``visioncell serve`` uses."""

from __future__ import annotations

import contextlib
import socket
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import uvicorn

from backend.api.limits import uvicorn_options
from backend.eventloop import run


@dataclass(frozen=True)
class RunningServer:
    """A started server: its base URL and the app it serves."""

    base: str
    app: Any


@contextlib.contextmanager
def run_uvicorn(
    app: Any, *, start_timeout_s: float = 60.0, ws_compression: bool = False
) -> Iterator[RunningServer]:
    """Serve ``app`` (lifespan included) on 127.0.0.1 at a port the kernel picks, on the
    event loop ``visioncell serve`` uses (uvloop when installed); stop it after."""
    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    port = sock.getsockname()[1]
    config = uvicorn.Config(
        app, log_level="warning", lifespan="on", **uvicorn_options(ws_compression=ws_compression)
    )
    server = uvicorn.Server(config)
    thread = threading.Thread(
        target=lambda: run(server.serve(sockets=[sock])), name="uvicorn", daemon=True
    )
    thread.start()
    deadline = time.monotonic() + start_timeout_s
    while not server.started and thread.is_alive() and time.monotonic() < deadline:
        time.sleep(0.05)
    try:
        if not server.started:
            raise RuntimeError("uvicorn did not start")
        yield RunningServer(f"http://127.0.0.1:{port}", app)
    finally:
        server.should_exit = True
        thread.join(timeout=30)
        sock.close()
