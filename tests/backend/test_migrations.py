"""Migrations go up and down cleanly on SQLite and on PostgreSQL."""

from __future__ import annotations

import asyncio
from datetime import UTC, datetime, timedelta, timezone

import pytest
from sqlalchemy import inspect, select
from sqlalchemy.exc import IntegrityError

from backend.db.migrate import downgrade, head_revision, upgrade
from backend.db.models import Base, Calibration, CalibrationKind, Cell
from backend.db.session import Database
from tests.utils.postgres import fresh_postgres_database

EXPECTED = set(Base.metadata.tables)


def _tables(url: str) -> set[str]:
    async def run() -> set[str]:
        db = Database(url)
        try:
            async with db.engine.connect() as conn:
                return set(await conn.run_sync(lambda c: inspect(c).get_table_names()))
        finally:
            await db.dispose()

    return asyncio.run(run()) - {"alembic_version"}


def _round_trip(url: str) -> None:
    downgrade(url, "base")
    assert _tables(url) == set()
    upgrade(url)
    assert _tables(url) == EXPECTED
    downgrade(url, "base")
    assert _tables(url) == set()
    upgrade(url)
    assert _tables(url) == EXPECTED


async def _timestamps_and_active_flag(url: str) -> None:
    db = Database(url)
    try:
        async with db.session() as s:
            await s.execute(Calibration.__table__.delete())
            await s.execute(Cell.__table__.delete())
        east = timezone(timedelta(hours=5))
        stamp = datetime(2026, 3, 1, 17, 30, tzinfo=east)
        async with db.session() as s:
            cell = Cell(name="tz-cell", created_at=stamp)
            s.add(cell)
            await s.flush()
            s.add(
                Calibration(
                    cell_id=cell.id,
                    kind=CalibrationKind.intrinsic,
                    parameters={},
                    sample_count=3,
                    active=True,
                )
            )
        async with db.session() as s:
            back = await s.scalar(select(Cell).where(Cell.name == "tz-cell"))
            assert back.created_at.tzinfo is not None
            assert back.created_at.utcoffset() == timedelta(0)
            assert back.created_at == stamp.astimezone(UTC)
        # At most one active calibration of a kind per cell: the database refuses a second.
        with pytest.raises(IntegrityError):
            async with db.session() as s:
                s.add(
                    Calibration(
                        cell_id=back.id,
                        kind=CalibrationKind.intrinsic,
                        parameters={},
                        sample_count=3,
                        active=True,
                    )
                )
        async with db.session() as s:
            n = len((await s.scalars(select(Calibration))).all())
        assert n == 1  # the refused row left nothing behind
    finally:
        await db.dispose()


def test_sqlite_migrations_round_trip(tmp_path):
    url = f"sqlite+aiosqlite:///{tmp_path / 'm.db'}"
    upgrade(url)
    _round_trip(url)
    asyncio.run(_timestamps_and_active_flag(url))
    assert head_revision() is not None


def test_postgresql_migrations_round_trip():
    # A database of its own: downgrading the shared one broke tests running beside this one.
    with fresh_postgres_database("migrations", migrate=False) as url:
        upgrade(url)
        _round_trip(url)
        asyncio.run(_timestamps_and_active_flag(url))
        downgrade(url, "base")
