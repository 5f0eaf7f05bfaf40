"""Factories for settings, databases, users and images used across the backend tests."""

from __future__ import annotations

import asyncio
import socket
from collections import deque
from pathlib import Path

import cv2
import numpy as np

from backend.auth import create_user
from backend.db.migrate import sqlite_file, upgrade
from backend.db.models import Role
from backend.db.session import Database
from backend.settings import Settings
from tests.utils import templates

TEST_SECRET = "test-secret-0123456789abcdef"


#: Ports this process handed out lately: two calls in a row (an HTTP and a 3D view port)
#: could get the same port back from the kernel once the first socket was closed.
_RECENT_PORTS: deque[int] = deque(maxlen=256)


def free_port() -> int:
    """A TCP port that was free a moment ago on 127.0.0.1, not one of the last 256 this
    process handed out."""
    for _ in range(100):
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = int(s.getsockname()[1])
        if port not in _RECENT_PORTS:
            _RECENT_PORTS.append(port)
            return port
    raise RuntimeError("no free port that was not handed out lately")


def make_image_folder(folder: Path, n: int = 3, *, size: tuple[int, int] = (160, 120)) -> Path:
    """Write ``n`` small distinct PNG images into ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(0)
    for i in range(n):
        img = rng.integers(0, 255, size=(size[1], size[0], 3), dtype=np.uint8)
        cv2.putText(img, str(i), (10, 60), cv2.FONT_HERSHEY_SIMPLEX, 2.0, (255, 255, 255), 3)
        cv2.imwrite(str(folder / f"img{i:02d}.png"), img)
    return folder


def make_settings(tmp_path: Path, **overrides: object) -> Settings:
    """Settings for a test: SQLite in ``tmp_path``, ideal driver running 20x real time,
    a folder camera on generated images, no 3D view, the automatic threshold recomputed
    by teaches only (unless overridden)."""
    values: dict[str, object] = {
        "database_url": f"sqlite+aiosqlite:///{tmp_path / 'test.db'}",
        "var_dir": tmp_path / "var",
        "driver": "ideal",
        "camera": "folder",
        "camera_folder": make_image_folder(tmp_path / "images"),
        "time_scale": 20.0,
        "secret_key": TEST_SECRET,
        "view3d_enabled": False,
        "bootstrap_operator": False,
        "http_port": free_port(),
        "viser_port": free_port(),
        # Off unless a test is about it: a recomputation after every upload would add
        # threshold rows and jobs at times the other tests do not control.
        "threshold_follow": False,
    }
    values.update(overrides)
    return Settings(**values)  # type: ignore[arg-type]


def migrate(settings: Settings) -> None:
    """Bring the test's database to head: a new SQLite file is a copy of this process's
    migrated template (:mod:`tests.utils.templates`), anything else is upgraded."""
    target = templates.sqlite_copy_target(settings.database_url)
    if target is not None:
        templates.copy_migrated(target)
    else:
        upgrade(settings.database_url)


async def _users(settings: Settings, roles: list[Role]) -> dict[str, str]:
    db = Database(settings.database_url)
    tokens = {}
    try:
        async with db.session() as s:
            for role in roles:
                _, tok = await create_user(
                    s, f"test-{role.name}", role, settings.secret_key.get_secret_value()
                )
                tokens[role.name] = tok
    finally:
        await db.dispose()
    return tokens


def make_tokens(settings: Settings) -> dict[str, str]:
    """One user per role; returns ``{role: token}``.

    On an untouched copy of the migrated template the users come from the users template
    (fresh tokens under the settings' secret); otherwise they are created here."""
    path = sqlite_file(settings.database_url)
    if path is not None and templates.is_pristine_copy(path):
        return templates.users_into(path, settings.secret_key.get_secret_value())
    return asyncio.run(_users(settings, list(Role)))


def auth(token: str) -> dict[str, str]:
    """Authorization header for ``token``."""
    return {"Authorization": f"Bearer {token}"}
