"""Migrated template databases, built once per test process and copied per test.

Migrating a fresh SQLite file to head runs every Alembic revision (about 0.2 s of CPU);
creating the four test users opens an engine of its own.  Both results are the same for
every test, so each test process (each xdist worker) builds them once:

- the *migrated* template: an empty database at head, as ``upgrade(url)`` leaves it;
- the *users* template: the migrated one plus one user per role, written through
  :func:`backend.auth.create_user` as :func:`tests.utils.factories.make_tokens` does.

A test's database is a file copy of a template (SQLite keeps no path inside the file).
Copies of the users template get fresh random tokens, hashed under the test's own secret,
so no two tests share a token.  The templates live in a temporary folder removed when the
process exits.
"""

from __future__ import annotations

import asyncio
import atexit
import secrets
import shutil
import sqlite3
import tempfile
import threading
from dataclasses import dataclass
from pathlib import Path

from backend.auth import TOKEN_PREFIX, create_user, hash_token
from backend.db.migrate import sqlite_file, upgrade
from backend.db.models import Role
from backend.db.session import Database

__all__ = ["copy_migrated", "is_pristine_copy", "sqlite_copy_target", "users_into"]

#: The secret the users template is first written with (copies re-hash their tokens).
_TEMPLATE_SECRET = "template-secret-0123456789abcdef"


@dataclass(frozen=True)
class _Templates:
    migrated: Path
    users: Path
    #: ``{role name: user id}`` in the users template.
    user_ids: dict[str, int]


_lock = threading.Lock()
_built: _Templates | None = None
#: Copies of the migrated template nobody has opened yet: path -> (size, mtime_ns, inode).
_pristine: dict[Path, tuple[int, int, int]] = {}


def _stamp(path: Path) -> tuple[int, int, int]:
    st = path.stat()
    return st.st_size, st.st_mtime_ns, st.st_ino


def _side_files(path: Path) -> list[Path]:
    return [path.with_name(path.name + s) for s in ("-wal", "-shm", "-journal")]


async def _create_users(url: str) -> dict[str, int]:
    db = Database(url)
    ids: dict[str, int] = {}
    try:
        async with db.session() as s:
            for role in Role:
                user, _ = await create_user(s, f"test-{role.name}", role, _TEMPLATE_SECRET)
                ids[role.name] = int(user.id)
    finally:
        await db.dispose()
    return ids


def _templates() -> _Templates:
    global _built
    with _lock:
        if _built is None:
            folder = Path(tempfile.mkdtemp(prefix="visioncell-templates-"))
            atexit.register(shutil.rmtree, folder, True)
            migrated, users = folder / "migrated.db", folder / "users.db"
            upgrade(f"sqlite+aiosqlite:///{migrated}")
            shutil.copyfile(migrated, users)
            ids = asyncio.run(_create_users(f"sqlite+aiosqlite:///{users}"))
            for path in (migrated, users):
                leftovers = [p for p in _side_files(path) if p.exists()]
                assert not leftovers, f"template {path} left {leftovers} behind"
            _built = _Templates(migrated, users, ids)
        return _built


def sqlite_copy_target(database_url: str) -> Path | None:
    """The file a template copy may be written to for ``database_url``: a SQLite file that
    does not exist yet (None otherwise: another dialect, in memory, or already there)."""
    path = sqlite_file(database_url)
    if path is None or path.exists() or any(p.exists() for p in _side_files(path)):
        return None
    return path


def copy_migrated(path: Path) -> None:
    """Write the migrated template to ``path`` (its folder is created)."""
    src = _templates().migrated
    path.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(src, path)
    _pristine[path.resolve()] = _stamp(path)


def is_pristine_copy(path: Path) -> bool:
    """True if ``path`` is a copy of the migrated template that nothing has touched since."""
    key = path.resolve()
    stamp = _pristine.get(key)
    if stamp is None or not path.exists() or any(p.exists() for p in _side_files(path)):
        return False
    return _stamp(path) == stamp


def users_into(path: Path, secret: str) -> dict[str, str]:
    """Replace the pristine copy at ``path`` by the users template with fresh tokens hashed
    under ``secret``; returns ``{role: token}``."""
    t = _templates()
    _pristine.pop(path.resolve(), None)
    shutil.copyfile(t.users, path)
    tokens = {role: TOKEN_PREFIX + secrets.token_urlsafe(32) for role in t.user_ids}
    conn = sqlite3.connect(path)
    try:
        with conn:
            for role, user_id in t.user_ids.items():
                tok = tokens[role]
                conn.execute(
                    "UPDATE api_tokens SET token_hash = ?, prefix = ? WHERE user_id = ?",
                    (hash_token(tok, secret), tok[:10], user_id),
                )
    finally:
        conn.close()
    return tokens
