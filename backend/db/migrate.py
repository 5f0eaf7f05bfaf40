"""Run the Alembic migrations programmatically (``visioncell db upgrade|downgrade``)."""

from __future__ import annotations

import functools
from pathlib import Path

from alembic import command
from alembic.config import Config
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory
from sqlalchemy.engine import make_url

from backend.resources import resource_dir

__all__ = [
    "MIGRATIONS_DIR",
    "alembic_config",
    "current_revision",
    "downgrade",
    "head_revision",
    "sqlite_file",
    "upgrade",
]

MIGRATIONS_DIR = resource_dir("migrations")


def alembic_config(database_url: str) -> Config:
    """An Alembic config pointing at ``migrations/`` and the given database."""
    cfg = Config()
    cfg.set_main_option("script_location", str(MIGRATIONS_DIR))
    cfg.set_main_option("sqlalchemy.url", database_url.replace("%", "%%"))
    return cfg


def sqlite_file(database_url: str) -> Path | None:
    """The file of a SQLite URL (``sqlite+aiosqlite:///FILE``, also the ``file:`` URI form
    with ``?uri=true``), or None for an in-memory database or another dialect."""
    url = make_url(database_url)
    if not url.get_backend_name().startswith("sqlite"):
        return None
    db = url.database or ""
    if url.query.get("uri") in ("true", "1") and db.startswith("file:"):
        db = db.removeprefix("file:").split("?", 1)[0]
        if url.query.get("mode") == "memory":
            return None
    if not db or db == ":memory:":
        return None
    return Path(db)


def _ensure_sqlite_dir(database_url: str) -> None:
    # Only the database file's own folder is created: never the settings' var_dir, and
    # nothing at all for PostgreSQL or an in-memory database.
    path = sqlite_file(database_url)
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)


def upgrade(database_url: str, revision: str = "head") -> None:
    """Apply migrations up to ``revision``.  Must not run inside an event loop."""
    _ensure_sqlite_dir(database_url)
    command.upgrade(alembic_config(database_url), revision)


def downgrade(database_url: str, revision: str = "base") -> None:
    """Revert migrations down to ``revision``.  Must not run inside an event loop."""
    command.downgrade(alembic_config(database_url), revision)


@functools.cache
def head_revision() -> str | None:
    """The newest revision in ``migrations/versions`` (read once per process: parsing the
    revision scripts took ~50 ms, on the event loop of every ``GET /api/status``)."""
    return ScriptDirectory.from_config(alembic_config("sqlite+aiosqlite://")).get_current_head()


async def current_revision(engine) -> str | None:
    """The revision the database is at (None if never migrated)."""
    async with engine.connect() as conn:
        return await conn.run_sync(lambda c: MigrationContext.configure(c).get_current_revision())
