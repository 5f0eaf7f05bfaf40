"""Start ``visioncell serve`` as a real process and drive headless Chromium against it."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import httpx
import pytest

from tests.utils.factories import TEST_SECRET, free_port, make_image_folder

CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--enable-unsafe-swiftshader",
]


def chromium_path() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        found = shutil.which(name)
        if found:
            return found
    return None


@dataclass
class Server:
    proc: subprocess.Popen[str]
    base: str
    viser: str
    env: dict[str, str]
    log: Path

    def token(self, name: str, role: str) -> str:
        r = subprocess.run(
            [sys.executable, "-m", "backend.cli", "user", "add", name, "--role", role],
            capture_output=True,
            text=True,
            env=self.env,
            timeout=60,
            check=True,
        )
        return r.stdout.strip().splitlines()[-1]

    def stop(self, timeout: float = 10.0) -> float:
        """Send SIGINT (as Ctrl-C does) and return how long the process took to exit."""
        t0 = time.monotonic()
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        return time.monotonic() - t0


def start_server(tmp_path: Path, *, ready_s: float = 300.0, **extra_env: str) -> Server:
    """``visioncell serve`` on free ports; ``ready_s`` only bounds a hang (a loaded machine
    takes long to start it)."""
    http_port, viser_port = free_port(), free_port()
    env = {
        **os.environ,
        "VISIONCELL_DATABASE_URL": f"sqlite+aiosqlite:///{tmp_path / 'e2e.db'}",
        "VISIONCELL_VAR_DIR": str(tmp_path / "var"),
        "VISIONCELL_HTTP_PORT": str(http_port),
        "VISIONCELL_VISER_PORT": str(viser_port),
        "VISIONCELL_SECRET_KEY": TEST_SECRET,
        "VISIONCELL_CAMERA_FOLDER": str(make_image_folder(tmp_path / "images", size=(320, 240))),
        # The quick console test runs the ideal arm and the image folder; the simulated
        # cell (the product's default) has its own test, which overrides these.
        "VISIONCELL_DRIVER": "ideal",
        "VISIONCELL_CAMERA": "folder",
        "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"),
        **extra_env,
    }
    log = tmp_path / "serve.log"
    proc = subprocess.Popen(
        [sys.executable, "-m", "backend.cli", "serve"],
        stdout=log.open("w"),
        stderr=subprocess.STDOUT,
        text=True,
        env=env,
    )
    server = Server(
        proc, f"http://127.0.0.1:{http_port}", f"http://127.0.0.1:{viser_port}", env, log
    )
    deadline = time.monotonic() + ready_s
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"visioncell serve exited early:\n{log.read_text()}")
        try:
            if httpx.get(f"{server.base}/api/health", timeout=1).status_code == 200:
                return server
        except httpx.HTTPError:
            pass
        time.sleep(0.3)
    server.stop()
    raise RuntimeError(f"visioncell serve did not answer within {ready_s:g} s:\n{log.read_text()}")


@pytest.fixture(scope="module")
def browser():
    exe = chromium_path()
    if exe is None:
        pytest.skip("no Chromium found (apt-get install chromium); .ci/run installs it")
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=exe, args=CHROMIUM_ARGS)
        yield b
        b.close()


@pytest.fixture
def server(tmp_path) -> Iterator[Server]:
    s = start_server(tmp_path)
    yield s
    s.stop()


@pytest.fixture(scope="module")
def shared_server(tmp_path_factory) -> Iterator[Server]:
    """One server for a module's tests that only read or make their own users."""
    s = start_server(tmp_path_factory.mktemp("shared-server"))
    yield s
    s.stop()
