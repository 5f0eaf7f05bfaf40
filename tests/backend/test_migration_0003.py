"""Revision 0003 (models' part; views' mask, thumbnail, yaw, roll, source, pose) goes up and
down and keeps existing rows: old models get their own name as part, old views the defaults."""

from __future__ import annotations

import asyncio

from sqlalchemy import inspect, text

from backend.db.migrate import downgrade, upgrade
from backend.db.session import Database
from tests.utils.postgres import fresh_postgres_database

NEW_VIEW_COLUMNS = {
    "mask_png",
    "thumbnail_jpeg",
    "width",
    "height",
    "yaw_rad",
    "roll_rad",
    "source",
    "joints",
    "T_base_cam",
}


def _columns(url: str, table: str) -> set[str]:
    async def run() -> set[str]:
        db = Database(url)
        try:
            async with db.engine.connect() as conn:
                cols = await conn.run_sync(lambda c: inspect(c).get_columns(table))
                return {c["name"] for c in cols}
        finally:
            await db.dispose()

    return asyncio.run(run())


async def _rows_at_0002(url: str) -> None:
    db = Database(url)
    try:
        async with db.session() as s:
            await s.execute(text("DELETE FROM trained_views"))
            await s.execute(text("DELETE FROM object_models"))
            await s.execute(
                text(
                    "INSERT INTO object_models (name, kind, sitting_base, description, created_at) "
                    "VALUES ('old-wheel', '2d', 'default', '', CURRENT_TIMESTAMP)"
                )
            )
            mid = (await s.execute(text("SELECT id FROM object_models"))).scalar_one()
            await s.execute(
                text(
                    "INSERT INTO trained_views (model_id, viewpoint, image_png, features, "
                    "descriptor_kind, descriptor_version, keypoint_count, created_at) "
                    "VALUES (:m, 1, :png, :f, 'sift', 'opencv-4', 5, CURRENT_TIMESTAMP)"
                ),
                {"m": mid, "png": b"\x89PNG", "f": b"npz"},
            )
    finally:
        await db.dispose()


async def _read(url: str) -> tuple[str, tuple]:
    db = Database(url)
    try:
        async with db.session() as s:
            part = (await s.execute(text("SELECT part FROM object_models"))).scalar_one()
            view = (
                await s.execute(
                    text("SELECT source, yaw_rad, roll_rad, width, mask_png FROM trained_views")
                )
            ).one()
            return part, tuple(view)
    finally:
        await db.dispose()


def _round_trip(url: str) -> None:
    upgrade(url)
    downgrade(url, "0002")
    assert "part" not in _columns(url, "object_models")
    assert not NEW_VIEW_COLUMNS & _columns(url, "trained_views")
    asyncio.run(_rows_at_0002(url))
    upgrade(url)
    assert "part" in _columns(url, "object_models")
    assert _columns(url, "trained_views") >= NEW_VIEW_COLUMNS
    part, view = asyncio.run(_read(url))
    assert part == "old-wheel"
    assert view == ("upload", 0.0, 0.0, 0, None)
    downgrade(url, "0002")
    upgrade(url)


def test_sqlite_0003_keeps_rows(tmp_path):
    _round_trip(f"sqlite+aiosqlite:///{tmp_path / 'm.db'}")


def test_postgresql_0003_keeps_rows():
    # A database of its own: downgrading the shared one broke tests running beside this one.
    with fresh_postgres_database("m0003", migrate=False) as url:
        _round_trip(url)
        downgrade(url, "base")
