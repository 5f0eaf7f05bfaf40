"""Revision 0014 (recipes, the active recipe per cell, the recipe of each inspection) goes
up and down on SQLite and PostgreSQL: the inspections stored before it keep their rows and
read as run under no recipe; the database itself refuses a recipe number out of 1..9999 or
twice in a cell, and a second active recipe for a cell."""

from __future__ import annotations

import asyncio
from datetime import UTC, datetime

import pytest
from sqlalchemy import text
from sqlalchemy.exc import IntegrityError

from backend.db.migrate import downgrade, upgrade
from backend.db.session import Database


def _when(url: str) -> object:
    t = datetime(2026, 1, 1, 10, tzinfo=UTC)
    return t.strftime("%Y-%m-%d %H:%M:%S") if url.startswith("sqlite") else t


async def _rows_at_0013(url: str) -> None:
    db = Database(url)
    try:
        async with db.session() as s:
            await s.execute(text("INSERT INTO cells (name, description, created_at) "
                                 "VALUES ('c-old', '', CURRENT_TIMESTAMP)"))  # fmt: skip
            cid = (await s.execute(text("SELECT id FROM cells WHERE name = 'c-old'"))).scalar_one()
            await s.execute(
                text("INSERT INTO inspections (cell_id, started_at, decision, viewpoints_visited,"
                     " note, policy, reason, durations, source) VALUES (:c, :t, 'unknown', '[1]',"
                     " '', 'naive', '', '{}', 'cell')"),
                {"c": cid, "t": _when(url)},
            )  # fmt: skip
    finally:
        await db.dispose()


_RECIPE = (
    "INSERT INTO recipes (cell_id, name, number, description, options, models, bins, "
    "created_at, updated_at) VALUES (:c, :n, :k, '', '{}', '[]', '{}', :t, :t)"
)


async def _use_0014(url: str) -> list[str]:
    """Rows of the new tables; what the database refused."""
    db = Database(url)
    refused = []
    try:
        async with db.session() as s:
            old = (await s.execute(text("SELECT recipe_id, recipe_name FROM inspections"))).all()
            assert [tuple(r) for r in old] == [(None, None)]
            cid = (await s.execute(text("SELECT id FROM cells WHERE name = 'c-old'"))).scalar_one()
            await s.execute(text(_RECIPE), {"c": cid, "n": "wheels", "k": 1, "t": _when(url)})
            rid = (await s.execute(text("SELECT id FROM recipes"))).scalar_one()
            await s.execute(
                text("INSERT INTO recipe_selections (cell_id, recipe_id, activated_at, "
                     "activated_by) VALUES (:c, :r, :t, 'cli')"),
                {"c": cid, "r": rid, "t": _when(url)},
            )  # fmt: skip
            await s.execute(
                text("INSERT INTO audit_log (at, actor, actor_role, kind, entity_id, action, "
                     "reason) VALUES (:t, 'cli', 'cli', 'recipe', :r, 'create', '')"),
                {"t": _when(url), "r": str(rid)},
            )  # fmt: skip
        for name, number in (("zero", 0), ("big", 10000), ("twice", 1)):
            with pytest.raises(IntegrityError):
                async with db.session() as s:
                    await s.execute(
                        text(_RECIPE), {"c": cid, "n": name, "k": number, "t": _when(url)}
                    )
            refused.append(name)
        with pytest.raises(IntegrityError):
            async with db.session() as s:
                await s.execute(
                    text("INSERT INTO recipe_selections (cell_id, recipe_id, activated_at, "
                         "activated_by) VALUES (:c, :r, :t, 'cli')"),
                    {"c": cid, "r": rid, "t": _when(url)},
                )  # fmt: skip
        refused.append("second active")
        async with db.session() as s:
            assert (await s.execute(text("SELECT count(*) FROM recipes"))).scalar_one() == 1
    finally:
        await db.dispose()
    return refused


async def _after_downgrade(url: str) -> tuple[int, int]:
    db = Database(url)
    try:
        async with db.session() as s:
            n = (await s.execute(text("SELECT count(*) FROM inspections"))).scalar_one()
            a = (await s.execute(text("SELECT count(*) FROM audit_log"))).scalar_one()
            return int(n), int(a)
    finally:
        await db.dispose()


def _check(url: str) -> None:
    upgrade(url, "0013")
    asyncio.run(_rows_at_0013(url))
    upgrade(url, "0014")
    assert asyncio.run(_use_0014(url)) == ["zero", "big", "twice", "second active"]
    downgrade(url, "0013")
    assert asyncio.run(_after_downgrade(url)) == (1, 0)  # the recipe's audit row went with it
    upgrade(url, "head")


def test_0014_sqlite(tmp_path) -> None:
    _check(f"sqlite+aiosqlite:///{tmp_path / 'm.db'}")


def test_0014_postgres(postgres_url) -> None:
    downgrade(postgres_url, "base")
    _check(postgres_url)
