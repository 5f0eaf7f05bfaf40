"""Revision 0013 (inspections.source, negative_images) goes up and down; the inspections
stored before it read as ``cell`` (SQLite and PostgreSQL)."""

from __future__ import annotations

import asyncio
from datetime import UTC, datetime

from sqlalchemy import text

from backend.db.migrate import downgrade, upgrade
from backend.db.session import Database


async def _row_at_0012(url: str) -> None:
    t = datetime(2026, 1, 1, 10, tzinfo=UTC)
    when = t.strftime("%Y-%m-%d %H:%M:%S") if url.startswith("sqlite") else t
    db = Database(url)
    try:
        async with db.session() as s:
            await s.execute(text("INSERT INTO cells (name, description, created_at) "
                                 "VALUES ('c-old', '', CURRENT_TIMESTAMP)"))  # fmt: skip
            cid = (await s.execute(text("SELECT id FROM cells WHERE name = 'c-old'"))).scalar_one()
            await s.execute(
                text("INSERT INTO inspections (cell_id, started_at, decision, viewpoints_visited,"
                     " note, policy, reason, durations) VALUES (:c, :t, 'unknown', '[1]', '',"
                     " 'naive', '', '{}')"),
                {"c": cid, "t": when},
            )  # fmt: skip
    finally:
        await db.dispose()


async def _read(url: str) -> tuple[list[str], int]:
    db = Database(url)
    try:
        async with db.session() as s:
            sources = list((await s.execute(text("SELECT source FROM inspections"))).scalars())
            n = (await s.execute(text("SELECT count(*) FROM negative_images"))).scalar_one()
            return sources, int(n)
    finally:
        await db.dispose()


def _check(url: str) -> None:
    upgrade(url, "0012")
    asyncio.run(_row_at_0012(url))
    upgrade(url, "0013")
    assert asyncio.run(_read(url)) == (["cell"], 0)
    downgrade(url, "0012")
    upgrade(url, "head")
    assert asyncio.run(_read(url)) == (["cell"], 0)


def test_0013_sqlite(tmp_path) -> None:
    _check(f"sqlite+aiosqlite:///{tmp_path / 'm.db'}")


def test_0013_postgres(postgres_url) -> None:
    downgrade(postgres_url, "base")
    _check(postgres_url)
