"""Storing inspection records in one transaction with one statement per table: the ids come
back in the records' order, every record keeps its images, stage rows and report record, and
the number of statements does not grow with the number of records (SQLite and PostgreSQL)."""

from __future__ import annotations

import asyncio
from datetime import UTC, datetime, timedelta

from sqlalchemy import event, func, select

from backend.db.migrate import upgrade
from backend.db.models import Inspection, InspectionImage, InspectionStage
from backend.db.session import Database
from backend.inspection.results import InspectionRecord, ViewRecord, store_all
from backend.reports import make_filters, summary
from benchmarks.reports_data import ensure_cells

START = datetime(2026, 11, 3, 9, 41, 7, tzinfo=UTC)


def _record(i: int) -> InspectionRecord:
    t = START + timedelta(seconds=3 * i)
    known = i % 3 != 2
    return InspectionRecord(
        started_at=t,
        finished_at=t + timedelta(seconds=1),
        decision="recognized" if known else "unknown",
        reason=f"uploaded image 'img{i}.png'",
        policy="image",
        model_name=f"m{i % 2}" if known else None,
        score=0.2 + 0.01 * i,
        viewpoints=(1,),
        scores={"m0": 0.01 * i, "m1": 0.02},
        durations={"acquire": 0.001 * (i + 1), "features": 0.02, "match": 0.01},
        views=(ViewRecord(1, b"\xff\xd8jpeg%d" % i, {"m0": 0.01 * i}),),
        source="upload",
    )


async def _store(url: str, n: int) -> tuple[list[int], int]:
    """Store ``n`` records at once; their ids and the statements it took."""
    db = Database(url)
    try:
        (cid,) = await ensure_cells(db, (f"cell-batch-{n}",))
        count = [0]

        def seen(*_args: object) -> None:
            count[0] += 1

        event.listen(db.engine.sync_engine, "before_cursor_execute", seen)
        ids = await store_all(db, cid, [_record(i) for i in range(n)])
        event.remove(db.engine.sync_engine, "before_cursor_execute", seen)
        async with db.session() as s:
            rows = (
                await s.execute(select(Inspection).where(Inspection.id.in_(ids)))
            ).scalars().all()  # fmt: skip
            by_id = {r.id: r for r in rows}
            assert [by_id[i].reason for i in ids] == [_record(k).reason for k in range(n)]
            assert [by_id[i].duration_s for i in ids] == [
                round(sum(_record(k).durations.values()), 4) for k in range(n)
            ]
            images = (
                await s.execute(
                    select(InspectionImage.inspection_id, InspectionImage.image_jpeg)
                    .where(InspectionImage.inspection_id.in_(ids))
                )
            ).all()  # fmt: skip
            assert sorted(images) == [(iid, b"\xff\xd8jpeg%d" % k) for k, iid in enumerate(ids)]
            stages = await s.scalar(
                select(func.count(InspectionStage.id)).where(InspectionStage.inspection_id.in_(ids))
            )
            assert stages == 3 * n
            report = await summary(s, make_filters(cell=f"cell-batch-{n}"))
            assert report["count"] == n
        return ids, count[0]
    finally:
        await db.dispose()


def _check(url: str) -> None:
    one_ids, one = asyncio.run(_store(url, 1))
    many_ids, many = asyncio.run(_store(url, 12))
    assert len(one_ids) == 1 and len(many_ids) == 12
    assert many_ids == sorted(many_ids) and min(many_ids) > one_ids[0]
    # One statement per table whatever the number of records (the report names of the
    # first batch of a model are added once).
    assert many <= one + 2, (one, many)


def test_store_all_batches_sqlite(tmp_path) -> None:
    url = f"sqlite+aiosqlite:///{tmp_path / 'batch.db'}"
    upgrade(url)
    _check(url)


def test_store_all_batches_postgres(postgres_url) -> None:
    _check(postgres_url)


def test_nothing_to_store_touches_nothing(tmp_path) -> None:
    url = f"sqlite+aiosqlite:///{tmp_path / 'empty.db'}"
    upgrade(url)
    ids, statements = asyncio.run(_store(url, 0))
    assert ids == [] and statements == 0
