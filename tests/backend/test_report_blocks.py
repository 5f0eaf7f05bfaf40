"""The report blocks (``backend.reports.blocks``): the reports read from them answer exactly
as the SQL over the raw rows (``backend.reports.sql``) for every kind of filter, on SQLite
and PostgreSQL; every write path keeps them in step, all or nothing; migration 0010 fills
them from the rows already stored; a deleted cell takes its blocks along."""

from __future__ import annotations

import asyncio
from collections.abc import Iterator
from datetime import UTC, datetime, timedelta
from typing import Any

import pytest
from sqlalchemy import MetaData, Table, delete, func, insert, select

from backend.db.migrate import upgrade
from backend.db.models import Cell, Inspection, InspectionInProgress, InspectionStage, ReportBlock
from backend.db.session import Database
from backend.inspection import results
from backend.inspection.recovery import mark_interrupted
from backend.inspection.results import InspectionRecord, store
from backend.reports import blocks, confusion, make_filters, sql, summary, timeseries
from backend.reports.blocks import RECORD
from backend.reports.stages import stage_rows
from benchmarks.reports_data import ensure_cells, generate_rows, insert_rows

START = datetime(2026, 9, 1, 5, 17, 3, 250_000, tzinfo=UTC)
#: The last microsecond of an hour: an inspection stored by ``store`` starts there.
EDGE = START + timedelta(hours=3, minutes=59, seconds=59, microseconds=999_999)


def _filters() -> Iterator[Any]:
    """Filters that cut blocks in every way: mid-hour edges, one instant, one hour, cells,
    models, decisions, policies, an unknown model and an empty range."""
    t = START + timedelta(hours=20, minutes=13, seconds=7)
    yield make_filters()
    yield make_filters(start=t, end=t + timedelta(hours=30, minutes=41))
    yield make_filters(start=t, end=t + timedelta(minutes=40), cell="cell-2")
    yield make_filters(start=START.replace(minute=0, second=0, microsecond=0),
                       end=START.replace(minute=0, second=0, microsecond=0) + timedelta(hours=1))  # fmt: skip
    yield make_filters(end=t, policy="two-views", decision="recognized")
    yield make_filters(start=t, model="wheel-a")
    yield make_filters(decision="failed", cell="cell-3")
    yield make_filters(decision="unknown", policy="top-only")
    yield make_filters(model="no-such-model")
    yield make_filters(start=EDGE, end=EDGE)  # both ends inclusive
    yield make_filters(start=EDGE - timedelta(minutes=30), end=EDGE, cell="cell-1")
    yield make_filters(start=EDGE, end=EDGE + timedelta(hours=2))
    yield make_filters(start=START - timedelta(days=3), end=START - timedelta(days=2))


async def _compare(db: Database) -> int:
    """Checks each filter's block answers against the SQL's; returns how many reports."""
    n = 0
    async with db.session() as s:
        for f in _filters():
            assert await summary(s, f) == await sql.summary(s, f), f
            assert await confusion(s, f) == await sql.confusion(s, f), f
            buckets = ("hour", "day") if f.start is None else ("minute", "hour", "day")
            for b in buckets:
                assert await timeseries(s, f, b) == await sql.timeseries(s, f, b), (f, b)  # type: ignore[arg-type]
            n += 2 + len(buckets)
    return n


def _record(t: datetime, **kw: Any) -> InspectionRecord:
    base: dict[str, Any] = {
        "started_at": t, "finished_at": t + timedelta(seconds=3), "decision": "recognized",
        "reason": "ok", "policy": "best-next", "model_name": "wheel-b", "score": 0.8125,
        "viewpoints": (1, 2), "durations": {"move": 1.25, "match": 0.0731, "pick": 2.0},
        "truth": {"name": "wheel-b"},
    }  # fmt: skip
    return InspectionRecord(**{**base, **kw})


async def _fill(url: str) -> Database:
    db = Database(url)
    ids = await ensure_cells(db)
    await insert_rows(db, generate_rows(700, ids, seed=11, start=START, period_s=240.0), chunk=97)
    # The inspection service's and the recovery's write paths, one row each and odd values.
    t = EDGE
    await store(db, ids[0], _record(t))
    await store(db, ids[1], _record(t + timedelta(seconds=1), decision="unknown",
                                    model_name=None, score=0.2, durations={}, truth=None))  # fmt: skip
    async with db.session() as s:
        s.add(InspectionInProgress(cell_id=ids[2], policy="naive", owner="elsewhere:999999",
                                   started_at=t + timedelta(minutes=5)))  # fmt: skip
    assert len(await mark_interrupted(db, ids[2])) == 1
    return db


async def _check_engine(url: str) -> dict[str, Any]:
    db = await _fill(url)
    try:
        assert await _compare(db) > 40
        async with db.session() as s:
            got = await summary(s, make_filters())
            assert got["count"] == 703
            return {"summary": got, "ts": await timeseries(s, make_filters(), "hour"),
                    "confusion": await confusion(s, make_filters())}  # fmt: skip
    finally:
        await db.dispose()


def test_blocks_answer_as_the_sql_sqlite(tmp_path) -> None:
    url = f"sqlite+aiosqlite:///{tmp_path / 'b.db'}"
    upgrade(url)
    asyncio.run(_check_engine(url))


def test_blocks_answer_as_the_sql_and_sqlite_postgres(postgres_url, tmp_path) -> None:
    url = f"sqlite+aiosqlite:///{tmp_path / 'b.db'}"
    upgrade(url)
    assert asyncio.run(_check_engine(postgres_url)) == asyncio.run(_check_engine(url))


def test_an_hour_splits_into_parts_and_still_answers_as_the_sql(tmp_path, monkeypatch) -> None:
    """Parts of at most MAX_RECORDS records (4 here, so that the 700 rows' hours split and
    the bulk loader's chunks cross part boundaries) answer exactly as one block would."""
    monkeypatch.setattr(blocks, "MAX_RECORDS", 4)
    url = f"sqlite+aiosqlite:///{tmp_path / 'b.db'}"
    upgrade(url)
    asyncio.run(_check_engine(url))

    async def sizes() -> list[tuple[int, int, int]]:
        db = Database(url)
        try:
            async with db.session() as s:
                rows = await s.execute(select(ReportBlock.cell_id, ReportBlock.start_s,
                                              ReportBlock.part, ReportBlock.n))  # fmt: skip
                return [(int(c), int(t), int(n)) for c, t, _p, n in rows.all()]
        finally:
            await db.dispose()

    got = asyncio.run(sizes())
    assert max(n for _, _, n in got) == 4 and len(got) > len({(c, t) for c, t, _ in got})


def test_parts_fill_the_last_one_then_start_new_ones(monkeypatch) -> None:
    monkeypatch.setattr(blocks, "MAX_RECORDS", 3)
    size = RECORD.itemsize
    rec = [bytes([i]) * size for i in range(8)]
    # 2 records stored, 6 new: the last part takes one, then parts of 3 and 2.
    out = blocks.parts(rec[0] + rec[1], 2, b"".join(rec[2:]), 6)
    assert [n for n, _ in out] == [3, 3, 2]
    assert b"".join(d for _, d in out) == b"".join(rec)
    assert blocks.parts(b"".join(rec[:3]), 3, rec[3], 1) == [(3, b"".join(rec[:3])), (1, rec[3])]
    assert blocks.parts(b"", 0, rec[0], 1) == [(1, rec[0])]


async def _blocks(db: Database) -> list[tuple[int, int, int, bytes]]:
    async with db.session() as s:
        rows = await s.execute(
            select(ReportBlock.cell_id, ReportBlock.start_s, ReportBlock.n, ReportBlock.data)
            .order_by(ReportBlock.cell_id, ReportBlock.start_s, ReportBlock.part)
        )  # fmt: skip
        return [(int(c), int(t), int(n), bytes(d)) for c, t, n, d in rows.all()]


async def _failed_write(url: str, monkeypatch: pytest.MonkeyPatch) -> None:
    db = Database(url)
    try:
        (cid,) = await ensure_cells(db, ("cell-1",))
        t = START + timedelta(minutes=1)
        await store(db, cid, _record(t))
        before = await _blocks(db)
        assert [n for _, _, n, _ in before] == [1]

        class Broken:
            def __init__(self, **kw: Any) -> None:
                raise RuntimeError("disk full while writing the scene")

        # The scene is written after the report record: its failure must undo the record.
        monkeypatch.setattr(results, "InspectionScene", Broken)
        with pytest.raises(RuntimeError, match="disk full"):
            await store(db, cid, _record(t + timedelta(seconds=5)), scene=b"s" * 10)
        monkeypatch.undo()
        assert await _blocks(db) == before
        async with db.session() as s:
            assert await s.scalar(select(func.count(Inspection.id))) == 1
            assert (await summary(s, make_filters()))["count"] == 1
    finally:
        await db.dispose()


def test_a_failed_write_leaves_the_blocks_unchanged_sqlite(tmp_path, monkeypatch) -> None:
    url = f"sqlite+aiosqlite:///{tmp_path / 'f.db'}"
    upgrade(url)
    asyncio.run(_failed_write(url, monkeypatch))


def test_a_failed_write_leaves_the_blocks_unchanged_postgres(postgres_url, monkeypatch) -> None:
    asyncio.run(_failed_write(postgres_url, monkeypatch))


def _table_at_0009() -> Table:
    """The inspections table as revision 0009 had it (the columns added later left out)."""
    later = {"source"}
    cols = [c._copy() for c in Inspection.__table__.c if c.name not in later]
    return Table("inspections", MetaData(), *cols)


async def _rows_without_blocks(url: str) -> None:
    """Inspections and stage rows as revision 0009 stored them (no report blocks)."""
    db = Database(url)
    try:
        ids = await ensure_cells(db)
        rows = list(generate_rows(300, ids, seed=5, start=START, period_s=200.0))
        old = _table_at_0009()
        async with db.session() as s:
            got = (await s.scalars(
                insert(old).returning(old.c.id, sort_by_parameter_order=True), rows
            )).all()  # fmt: skip
            await s.execute(insert(InspectionStage),
                            [st for i, r in zip(got, rows, strict=True) for st in stage_rows(i, r)])  # fmt: skip
    finally:
        await db.dispose()


async def _after_0010(url: str) -> None:
    db = Database(url)
    try:
        blocks = await _blocks(db)
        assert sum(n for _, _, n, _ in blocks) == 300
        assert all(len(d) == n * RECORD.itemsize for _, _, n, d in blocks)
        assert await _compare(db) > 40
    finally:
        await db.dispose()


def _migrate(url: str) -> None:
    upgrade(url, "0009")
    asyncio.run(_rows_without_blocks(url))
    upgrade(url, "0010")
    asyncio.run(_after_0010(url))


def test_0010_fills_the_blocks_sqlite(tmp_path) -> None:
    _migrate(f"sqlite+aiosqlite:///{tmp_path / 'm.db'}")


def test_0010_fills_the_blocks_postgres(postgres_url) -> None:
    from backend.db.migrate import downgrade

    downgrade(postgres_url, "base")
    _migrate(postgres_url)


def test_a_deleted_cell_takes_its_blocks_along(tmp_path) -> None:
    url = f"sqlite+aiosqlite:///{tmp_path / 'c.db'}"
    upgrade(url)

    async def run() -> None:
        db = Database(url)
        try:
            a, b = await ensure_cells(db, ("cell-1", "cell-2"))
            await store(db, a, _record(START))
            await store(db, b, _record(START))
            async with db.session() as s:
                await s.execute(delete(Cell).where(Cell.id == a))
            assert [c for c, _, _, _ in await _blocks(db)] == [b]
            async with db.session() as s:
                assert (await summary(s, make_filters()))["count"] == 1
                assert await summary(s, make_filters()) == await sql.summary(s, make_filters())
        finally:
            await db.dispose()

    asyncio.run(run())


def test_concurrent_writes_to_one_block_lose_no_record_postgres(postgres_url) -> None:
    """Two cells' processes (here: tasks on their own connections) append to the same
    blocks at once: the row lock serialises them, every record arrives."""

    async def run() -> None:
        dbs = [Database(postgres_url) for _ in range(4)]
        try:
            ids = await ensure_cells(dbs[0], ("cell-1", "cell-2"))
            t = START.replace(minute=0, second=0, microsecond=0)
            await asyncio.gather(*[
                store(dbs[k % 4], ids[k % 2], _record(t + timedelta(seconds=k), model_name=f"m-{k % 3}"))
                for k in range(24)
            ])  # fmt: skip
            blocks = await _blocks(dbs[0])
            assert [(n, len(d)) for _, _, n, d in blocks] == [(12, 12 * RECORD.itemsize)] * 2
            async with dbs[0].session() as s:
                got = await summary(s, make_filters())
                assert got["count"] == 24
                assert got == await sql.summary(s, make_filters())
        finally:
            for db in dbs:
                await db.dispose()

    asyncio.run(run())
