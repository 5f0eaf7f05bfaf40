"""A fresh, migrated PostgreSQL database per test on the server named by
``VISIONCELL_TEST_POSTGRES_URL`` (CI: ``postgresql+asyncpg://postgres@127.0.0.1:5432/test``).

Use the :func:`postgres_url` fixture (import it into a ``conftest.py``) or the
:func:`fresh_postgres_database` context manager; both skip the test with the reason when the
variable is unset.  The database's name is ``vc_<tag>_<random>``; it is dropped afterwards
(connections still open are terminated first).
"""

from __future__ import annotations

import asyncio
import os
import re
import uuid
from collections.abc import Iterator
from contextlib import contextmanager

import pytest
from sqlalchemy.engine import make_url

from backend.db.migrate import upgrade

__all__ = ["ENV", "fresh_postgres_database", "postgres_url", "server_url"]

#: The environment variable with the server's URL (any database on it).
ENV = "VISIONCELL_TEST_POSTGRES_URL"
_NAME = re.compile(r"^[a-z][a-z0-9_]{0,62}$")


def server_url() -> str | None:
    """The configured server URL, or None."""
    return os.environ.get(ENV) or None


async def _admin(url: str, sql: str) -> None:
    import asyncpg

    u = make_url(url)
    conn = await asyncpg.connect(
        host=u.host or "127.0.0.1",
        port=u.port or 5432,
        user=u.username or "postgres",
        password=u.password,
        database="postgres",  # the maintenance database: the URL's own may not exist
    )
    try:
        await conn.execute(sql)
    finally:
        await conn.close()


@contextmanager
def fresh_postgres_database(tag: str = "test", *, migrate: bool = True) -> Iterator[str]:
    """Create ``vc_<tag>_<random>`` on the test server, migrate it to head (Alembic) and
    yield its async URL; drop it afterwards.  Skips when :data:`ENV` is unset."""
    base = server_url()
    if base is None:
        pytest.skip(f"{ENV} is not set (CI sets it to the local PostgreSQL server)")
    if not base.startswith("postgresql+asyncpg://"):
        raise ValueError(f"{ENV} must be a postgresql+asyncpg:// URL, got {base!r}")
    name = f"vc_{tag}_{uuid.uuid4().hex[:10]}"
    if not _NAME.match(name):
        raise ValueError(f"tag must make a plain lower-case database name, got {tag!r}")
    asyncio.run(_admin(base, f'CREATE DATABASE "{name}"'))
    url = make_url(base).set(database=name).render_as_string(hide_password=False)
    try:
        if migrate:
            upgrade(url)
        yield url
    finally:
        asyncio.run(_admin(base, f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)'))


@pytest.fixture
def postgres_url(request: pytest.FixtureRequest) -> Iterator[str]:
    """URL of a fresh migrated PostgreSQL database for this test (see the module doc).

    The name's tag is the test module's name part after ``test_`` (trimmed)."""
    module = request.module.__name__.rsplit(".", 1)[-1].removeprefix("test_")
    tag = re.sub(r"[^a-z0-9_]", "_", module.lower())[:30] or "test"
    with fresh_postgres_database(tag) as url:
        yield url
