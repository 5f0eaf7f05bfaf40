"""Report queries over generated inspections on SQLite and PostgreSQL (issue 15 target:
<= 200 ms p95 over 100,000 inspections on both engines).

Generates ``--rows`` inspections (:mod:`benchmarks.reports_data`: three cells, six models,
four policies, about seven weeks; the loader writes the report blocks in each chunk's
transaction, as the inspection service does) plus ``--images`` small JPEG-sized blobs,
into a fresh SQLite file and a fresh PostgreSQL database (``--postgres URL``, default
``VISIONCELL_TEST_POSTGRES_URL``; skipped when neither is given), migrated to head.  Then
each report route's query (the service function the route calls, on one session) is timed
``--repeats`` times, and, as the baseline in the same run, the same report computed by the
SQL over the raw rows (:mod:`backend.reports.sql`, with the indexes of migration 0007);
every baseline answer is checked equal to the route's.  Export and storage have no second
path: their baseline column repeats the route.  Prints p50 and p95 per route and engine and
the ratio.

Run ``python -m benchmarks.reports [--rows N] [--repeats N] [--postgres URL] [--json]``.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import statistics
import sys
import tempfile
import time
import uuid
from collections.abc import Awaitable, Callable
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.table import Table
from sqlalchemy import insert, select, text
from sqlalchemy.engine import make_url

from backend.db.migrate import upgrade
from backend.db.models import Inspection, InspectionImage
from backend.db.session import Database
from backend.reports import (
    check_export,
    confusion,
    make_filters,
    sql,
    storage_used,
    summary,
    timeseries,
)
from backend.reports.export import export_rows
from benchmarks.reports_data import ensure_cells, generate_rows, insert_rows

out = Console()
err = Console(stderr=True)

START = datetime(2026, 9, 1, tzinfo=UTC)


Route = Callable[[Any, Database], Awaitable[Any]]


def _routes(t_last: datetime) -> list[tuple[str, Route, Route | None]]:
    """(name, the route's query, its raw-SQL baseline or None)."""
    week = make_filters(start=t_last - timedelta(days=7), end=t_last, cell="cell-1")
    day = make_filters(start=t_last - timedelta(days=1), end=t_last)
    every = make_filters()
    model = make_filters(model="wheel-a")

    async def first_page(s: Any, db: Database) -> Any:
        await check_export(db, every)
        n = 0
        async for _ in export_rows(db, every):
            n += 1
            if n >= 1000:
                break
        return n

    return [
        ("summary (all)", lambda s, db: summary(s, every), lambda s, db: sql.summary(s, every)),
        ("summary (cell, 7 days)", lambda s, db: summary(s, week),
         lambda s, db: sql.summary(s, week)),
        ("summary (model)", lambda s, db: summary(s, model), lambda s, db: sql.summary(s, model)),
        ("timeseries hour (all)", lambda s, db: timeseries(s, every, "hour"),
         lambda s, db: sql.timeseries(s, every, "hour")),
        ("timeseries minute (1 day)", lambda s, db: timeseries(s, day, "minute"),
         lambda s, db: sql.timeseries(s, day, "minute")),
        ("confusion (all)", lambda s, db: confusion(s, every),
         lambda s, db: sql.confusion(s, every)),
        ("export first 1000 rows", first_page, None),
        ("storage", lambda s, db: storage_used(s), None),
    ]  # fmt: skip


async def _fill(db: Database, rows: int, images: int) -> datetime:
    ids = await ensure_cells(db)
    t = time.perf_counter()
    await insert_rows(db, generate_rows(rows, ids, seed=1, start=START), chunk=5000,
                      progress=lambda n: err.print(f"  inserted {n}/{rows}", end="\r"))  # fmt: skip
    err.print(f"  inserted {rows} inspections in {time.perf_counter() - t:.1f} s")
    blob = b"\xff\xd8" + os.urandom(2046)
    async with db.session() as s:
        first = await s.scalar(select(Inspection.id).order_by(Inspection.id).limit(1))
        last_t = await s.scalar(
            select(Inspection.started_at).order_by(Inspection.id.desc()).limit(1)
        )
    for k in range(0, images, 2000):
        async with db.session() as s:
            await s.execute(insert(InspectionImage), [
                {"inspection_id": first + i, "viewpoint": 1, "image_jpeg": blob, "scores": {}}
                for i in range(k, min(images, k + 2000))
            ])  # fmt: skip
    if db.url.startswith("postgresql"):
        async with db.engine.begin() as conn:
            await conn.execute(text("ANALYZE"))
    else:
        async with db.engine.begin() as conn:
            await conn.execute(text("ANALYZE"))
    assert last_t is not None
    return last_t


async def _time1(db: Database, fn: Route, repeats: int) -> tuple[list[float], Any]:
    times, ans = [], None
    for _ in range(repeats + 1):  # the first one warms caches and is dropped
        async with db.session() as s:
            t = time.perf_counter()
            ans = await fn(s, db)
            times.append(time.perf_counter() - t)
    return times[1:], ans


def _p95(v: list[float]) -> float:
    s = sorted(v)
    return s[-(-95 * len(s) // 100) - 1]


async def _engine(url: str, rows: int, images: int, repeats: int) -> dict[str, Any]:
    await asyncio.to_thread(upgrade, url)
    db = Database(url)
    res: dict[str, Any] = {}
    try:
        t_last = await _fill(db, rows, images)
        for name, fn, base in _routes(t_last):
            now, ans = await _time1(db, fn, repeats)
            was, ref = (now, ans) if base is None else await _time1(db, base, repeats)
            if ref != ans:
                raise AssertionError(f"{name}: the baseline answers differently")
            res[name] = {
                "p50_ms": round(1e3 * statistics.median(now), 2),
                "p95_ms": round(1e3 * _p95(now), 2),
                "base_p50_ms": round(1e3 * statistics.median(was), 2),
                "base_p95_ms": round(1e3 * _p95(was), 2),
            }
            err.print(f"  {name}: p50 {res[name]['p50_ms']:.1f} ms, "
                      f"baseline {res[name]['base_p50_ms']:.1f} ms")  # fmt: skip
    finally:
        await db.dispose()
    return res


async def _admin(url: str, sql: str) -> None:
    import asyncpg

    u = make_url(url)
    conn = await asyncpg.connect(host=u.host or "127.0.0.1", port=u.port or 5432,
                                 user=u.username or "postgres", password=u.password,
                                 database="postgres")  # fmt: skip
    try:
        await conn.execute(sql)
    finally:
        await conn.close()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rows", type=int, default=100_000)
    ap.add_argument("--images", type=int, default=20_000)
    ap.add_argument("--repeats", type=int, default=20)
    ap.add_argument("--postgres", default=os.environ.get("VISIONCELL_TEST_POSTGRES_URL"))
    ap.add_argument("--no-sqlite", action="store_true")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    if not 1 <= a.rows <= 2_000_000 or not 0 <= a.images <= a.rows or not 3 <= a.repeats <= 1000:
        ap.error(f"need 1 <= --rows <= 2e6, 0 <= --images <= rows, 3 <= --repeats <= 1000; "
                 f"got {a.rows}, {a.images}, {a.repeats}")  # fmt: skip
    results: dict[str, dict[str, Any]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        if not a.no_sqlite:
            err.print("SQLite")
            url = f"sqlite+aiosqlite:///{Path(tmp) / 'reports.db'}"
            results["sqlite"] = asyncio.run(_engine(url, a.rows, a.images, a.repeats))
    if a.postgres:
        name = f"vc_bench_reports_{uuid.uuid4().hex[:8]}"
        asyncio.run(_admin(a.postgres, f'CREATE DATABASE "{name}"'))
        try:
            err.print("PostgreSQL")
            url = make_url(a.postgres).set(database=name).render_as_string(hide_password=False)
            results["postgresql"] = asyncio.run(_engine(url, a.rows, a.images, a.repeats))
        finally:
            asyncio.run(_admin(a.postgres, f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)'))
    else:
        err.print("PostgreSQL skipped: give --postgres URL or set VISIONCELL_TEST_POSTGRES_URL")
    table = Table(title=f"Report queries over {a.rows} inspections ({a.repeats} repeats)")
    for c in ("route", "engine", "p50 ms", "p95 ms", "SQL p50", "SQL p95", "p95 ratio"):
        table.add_column(c, justify="left" if c in ("route", "engine") else "right")
    for eng, res in results.items():
        for name, r in res.items():
            table.add_row(name, eng, f"{r['p50_ms']:.1f}", f"{r['p95_ms']:.1f}",
                          f"{r['base_p50_ms']:.1f}", f"{r['base_p95_ms']:.1f}",
                          f"{r['base_p95_ms'] / max(r['p95_ms'], 1e-9):.1f}x")  # fmt: skip
    out.print(table)
    worst = {eng: max(r["p95_ms"] for r in res.values()) for eng, res in results.items()}
    out.print("worst p95: " + ", ".join(f"{e} {v:.1f} ms" for e, v in worst.items())
              + " (target 200 ms)")  # fmt: skip
    if a.json:
        print(json.dumps({"rows": a.rows, "repeats": a.repeats, "results": results,
                          "worst_p95_ms": worst}))  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
