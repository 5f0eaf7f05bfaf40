"""Bug: ``visioncell db upgrade`` created folders that the database URL does not name
(``var/``, or a folder literally called ``file:...`` for SQLite's URI form).  Only the
database file's own folder is created, and nothing for PostgreSQL or in-memory URLs."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from backend.db.migrate import sqlite_file
from tests.utils.factories import TEST_SECRET

VISIONCELL = Path(sys.executable).with_name("visioncell")


def _upgrade(cwd: Path, url: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "VISIONCELL_DATABASE_URL": url, "VISIONCELL_SECRET_KEY": TEST_SECRET}
    env.pop("VISIONCELL_VAR_DIR", None)
    return subprocess.run(
        [str(VISIONCELL), "db", "upgrade"],
        cwd=cwd,
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )


def _tree(root: Path) -> set[str]:
    return {str(p.relative_to(root)) for p in root.rglob("*")}


def test_upgrade_elsewhere_leaves_the_working_folder_alone(tmp_path):
    cwd, other = tmp_path / "cwd", tmp_path / "plant" / "db"
    cwd.mkdir()
    r = _upgrade(cwd, f"sqlite+aiosqlite:///{other / 'cell.db'}")
    assert r.returncode == 0, r.stderr
    assert (other / "cell.db").is_file()
    assert _tree(cwd) == set()  # no var/


def test_uri_form_creates_the_named_folder_only(tmp_path):
    r = _upgrade(tmp_path, "sqlite+aiosqlite:///file:dbdir/cell.db?mode=rwc&uri=true")
    assert r.returncode == 0, r.stderr
    assert _tree(tmp_path) == {"dbdir", "dbdir/cell.db"}


def test_in_memory_upgrade_creates_nothing(tmp_path):
    r = _upgrade(tmp_path, "sqlite+aiosqlite://")
    assert r.returncode == 0, r.stderr
    assert _tree(tmp_path) == set()


@pytest.mark.parametrize(
    ("url", "path"),
    [
        ("sqlite+aiosqlite:///var/visioncell.db", Path("var/visioncell.db")),
        ("sqlite+aiosqlite:////abs/x.db?timeout=5", Path("/abs/x.db")),
        ("sqlite+aiosqlite:///file:d/x.db?mode=rwc&uri=true", Path("d/x.db")),
        ("sqlite+aiosqlite:///file:x?mode=memory&uri=true", None),
        ("sqlite+aiosqlite://", None),
        ("sqlite+aiosqlite:///:memory:", None),
        ("postgresql+asyncpg://postgres@127.0.0.1/visioncell", None),
    ],
)
def test_sqlite_file_of_a_url(url, path):
    assert sqlite_file(url) == path
