"""Revision 0007 (inspection_stages, inspection_scenes, report indexes) goes up and down and
copies the stage durations of the inspections already stored (SQLite and PostgreSQL)."""

from __future__ import annotations

import asyncio
from datetime import UTC, datetime

from sqlalchemy import text

from backend.db.migrate import downgrade, upgrade
from backend.db.session import Database


def _t(url: str, i: int) -> object:
    t = datetime(2026, 1, i + 1, 10, tzinfo=UTC)
    return t.strftime("%Y-%m-%d %H:%M:%S") if url.startswith("sqlite") else t


async def _rows_at_0006(url: str) -> None:
    db = Database(url)
    try:
        async with db.session() as s:
            await s.execute(text("INSERT INTO cells (name, description, created_at) "
                                 "VALUES ('c-old', '', CURRENT_TIMESTAMP)"))  # fmt: skip
            cid = (await s.execute(text("SELECT id FROM cells WHERE name = 'c-old'"))).scalar_one()
            for i, dur in enumerate(('{"move": 1.5, "segment": 0.25}', "{}", '{"pick": 2.0}')):
                await s.execute(
                    text(
                        "INSERT INTO inspections (cell_id, started_at, decision, viewpoints_visited,"
                        " note, policy, reason, durations, model_name) VALUES (:c, :t, :d, '[1]',"
                        " '', 'naive', '', :j, :m)"
                    ),
                    {"c": cid, "t": _t(url, i), "d": "recognized", "j": dur,
                     "m": "wheel"},
                )  # fmt: skip
    finally:
        await db.dispose()


async def _stages(url: str) -> list[tuple[str, float, str, str]]:
    db = Database(url)
    try:
        async with db.session() as s:
            rows = await s.execute(text(
                "SELECT stage, seconds, policy, model_name FROM inspection_stages ORDER BY stage"
            ))  # fmt: skip
            return [tuple(r) for r in rows.all()]  # type: ignore[misc]
    finally:
        await db.dispose()


def _check(url: str) -> None:
    upgrade(url, "0006")
    asyncio.run(_rows_at_0006(url))
    upgrade(url, "0007")
    assert asyncio.run(_stages(url)) == [
        ("move", 1.5, "naive", "wheel"), ("pick", 2.0, "naive", "wheel"),
        ("segment", 0.25, "naive", "wheel"),
    ]  # fmt: skip
    downgrade(url, "0006")
    upgrade(url, "head")


def test_0007_backfills_stages_sqlite(tmp_path) -> None:
    _check(f"sqlite+aiosqlite:///{tmp_path / 'm.db'}")


def test_0007_backfills_stages_postgres(postgres_url) -> None:
    downgrade(postgres_url, "base")
    _check(postgres_url)
