"""Revision 0002 (calibration sample names) goes up and down and keeps existing rows."""

from __future__ import annotations

import asyncio

from sqlalchemy import inspect, text

from backend.db.migrate import downgrade, upgrade
from backend.db.session import Database
from tests.utils.postgres import fresh_postgres_database


def _sample_columns(url: str) -> set[str]:
    async def run() -> set[str]:
        db = Database(url)
        try:
            async with db.engine.connect() as conn:
                cols = await conn.run_sync(lambda c: inspect(c).get_columns("calibration_samples"))
                return {c["name"] for c in cols}
        finally:
            await db.dispose()

    return asyncio.run(run())


async def _add_sample_at_0001(url: str) -> None:
    db = Database(url)
    try:
        async with db.session() as s:
            await s.execute(text("DELETE FROM calibration_samples"))
            await s.execute(text("DELETE FROM calibration_sessions"))
            await s.execute(text("DELETE FROM cells WHERE name = 'mig-cell'"))
            await s.execute(
                text(
                    "INSERT INTO cells (name, description, created_at) VALUES ('mig-cell', '', CURRENT_TIMESTAMP)"
                )
            )
            cell = (
                await s.execute(text("SELECT id FROM cells WHERE name = 'mig-cell'"))
            ).scalar_one()
            await s.execute(
                text(
                    "INSERT INTO calibration_sessions (cell_id, kind, source, board, note, created_at) "
                    "VALUES (:c, 'intrinsic', 'upload', '{}', '', CURRENT_TIMESTAMP)"
                ),
                {"c": cell},
            )
            sid = (await s.execute(text("SELECT max(id) FROM calibration_sessions"))).scalar_one()
            await s.execute(
                text(
                    'INSERT INTO calibration_samples (session_id, "index", image_png, accepted, reason, created_at) '
                    "VALUES (:s, 0, :png, false, 'old', CURRENT_TIMESTAMP)"
                ),
                {"s": sid, "png": b"\x89PNG"},
            )
    finally:
        await db.dispose()


async def _names(url: str) -> list[str]:
    db = Database(url)
    try:
        async with db.session() as s:
            return list((await s.execute(text("SELECT name FROM calibration_samples"))).scalars())
    finally:
        await db.dispose()


def _round_trip(url: str) -> None:
    upgrade(url)
    assert "name" in _sample_columns(url)
    downgrade(url, "0001")
    assert "name" not in _sample_columns(url)
    asyncio.run(_add_sample_at_0001(url))
    upgrade(url)
    assert "name" in _sample_columns(url)
    assert asyncio.run(_names(url)) == [""]  # the old row got the empty default


def test_sqlite_0002_round_trip(tmp_path):
    _round_trip(f"sqlite+aiosqlite:///{tmp_path / 'm.db'}")


def test_postgresql_0002_round_trip():
    # A database of its own: downgrading the shared one broke tests running beside this one.
    with fresh_postgres_database("m0002", migrate=False) as url:
        _round_trip(url)
        downgrade(url, "base")
