"""The report aggregations against a Python computation, on SQLite and on PostgreSQL, and
the two engines against each other (the short version of ``benchmarks/reports.py``)."""

from __future__ import annotations

import asyncio
import itertools
import statistics
from collections import Counter
from datetime import UTC, datetime, timedelta
from typing import Any

import pytest

from backend.db.migrate import upgrade
from backend.db.session import Database
from backend.reports import confusion, export_rows, make_filters, summary, timeseries
from backend.reports.queries import STAGES
from backend.reports.stats import nearest_rank
from benchmarks.reports_data import ensure_cells, generate_rows, insert_rows
from vision.errors import InvalidInput, NotFound

N = 400
START = datetime(2026, 9, 1, tzinfo=UTC)


def _rows(cell_ids: list[int]) -> list[dict[str, Any]]:
    return list(generate_rows(N, cell_ids, seed=7, start=START, period_s=300.0))


async def _fill(url: str) -> tuple[Database, list[dict[str, Any]], dict[str, int]]:
    db = Database(url)
    ids = await ensure_cells(db)
    rows = _rows(ids)
    await insert_rows(db, iter(rows), chunk=150)
    return db, rows, dict(zip(("cell-1", "cell-2", "cell-3"), ids, strict=True))


def _pct(values: list[float], p: int) -> float | None:
    if not values:
        return None
    s = sorted(values)
    return s[-(-p * len(s) // 100) - 1]  # ceil(p n / 100), 1-based


def _expected_summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
    by = Counter(r["decision"] for r in rows)
    durs = [r["duration_s"] for r in rows]
    stages = {}
    for s in STAGES:
        v = [r["durations"][s] for r in rows if s in r["durations"]]
        if v:
            stages[s] = {"mean": round(statistics.fmean(v), 6), "p50": _pct(v, 50), "p95": _pct(v, 95)}  # fmt: skip
    models = sorted({r["model_name"] for r in rows if r["model_name"]})
    per_model = []
    for m in models:
        sc = [r["score"] for r in rows if r["model_name"] == m]
        counts = [0] * 10
        for x in sc:
            counts[min(int(x * 10), 9)] += 1
        per_model.append({"model": m, "count": len(sc), "p50": _pct(sc, 50), "p95": _pct(sc, 95),
                          "min": min(sc), "max": max(sc), "counts": counts})  # fmt: skip
    return {
        "count": len(rows),
        "by_decision": {d: by.get(d, 0) for d in ("recognized", "unknown", "failed")},
        "cycle": {
            "p50": _pct(durs, 50),
            "p95": _pct(durs, 95),
            "p99": _pct(durs, 99),
            "max": max(durs),
            "mean": round(statistics.fmean(durs), 6),
        },
        "stages": stages,
        "views_mean": round(sum(len(r["viewpoints_visited"]) for r in rows) / len(rows), 6),
        "per_model": per_model,
    }


async def _check_engine(url: str) -> dict[str, Any]:
    db, rows, cells = await _fill(url)
    try:
        async with db.session() as s:
            got = await summary(s, make_filters())
            exp = _expected_summary(rows)
            assert got["count"] == exp["count"] == N
            assert got["by_decision"] == exp["by_decision"]
            assert got["yield"] == round(exp["by_decision"]["recognized"] / N, 6)
            for k in ("p50", "p95", "p99", "max"):
                assert got["cycle_s"][k] == exp["cycle"][k], k
            assert got["cycle_s"]["mean"] == pytest.approx(exp["cycle"]["mean"], abs=2e-6)
            assert set(got["stages"]) == set(exp["stages"])
            for st, e in exp["stages"].items():
                assert got["stages"][st]["p50"] == e["p50"] and got["stages"][st]["p95"] == e["p95"]
                assert got["stages"][st]["mean"] == pytest.approx(e["mean"], abs=2e-6)
            assert got["views_mean"] == exp["views_mean"]
            assert [m["model"] for m in got["per_model"]] == [m["model"] for m in exp["per_model"]]
            for g, e in zip(got["per_model"], exp["per_model"], strict=True):
                assert g["count"] == e["count"]
                assert g["score"] == {"p50": e["p50"], "p95": e["p95"], "min": e["min"], "max": e["max"]}  # fmt: skip
                assert g["hist"]["counts"] == e["counts"]
                assert len(g["hist"]["edges"]) == 11
            assert got["first"] == min(r["started_at"] for r in rows).isoformat()
            assert got["last"] == max(r["started_at"] for r in rows).isoformat()

            # Filters: one cell, one policy, a time window; the count matches Python's.
            t0 = START + timedelta(hours=10)
            t1 = START + timedelta(hours=30)
            f = make_filters(start=t0, end=t1, cell="cell-2", policy="two-views")
            sub = [r for r in rows if r["cell_id"] == cells["cell-2"] and r["policy"] == "two-views"
                   and t0 <= r["started_at"] <= t1]  # fmt: skip
            got_f = await summary(s, f)
            assert got_f["count"] == len(sub) > 0
            assert got_f["cycle_s"]["p95"] == _pct([r["duration_s"] for r in sub], 95)
            assert got_f["filters"]["cell"] == "cell-2"
            got_m = await summary(s, make_filters(model="wheel-a"))
            assert got_m["count"] == sum(r["model_name"] == "wheel-a" for r in rows)
            got_d = await summary(s, make_filters(decision="failed"))
            assert got_d["by_decision"]["failed"] == got_d["count"] == exp["by_decision"]["failed"]

            # Time series: hour buckets, contiguous, counts add up, medians per bucket.
            ts = await timeseries(s, make_filters(), "hour")
            assert sum(b["count"] for b in ts["data"]) == N
            ts_t = [datetime.fromisoformat(b["t"]) for b in ts["data"]]
            assert all(b - a == timedelta(hours=1) for a, b in itertools.pairwise(ts_t))
            for b in ts["data"]:
                t = datetime.fromisoformat(b["t"])
                inb = [r for r in rows if t <= r["started_at"] < t + timedelta(hours=1)]
                assert b["count"] == len(inb)
                assert b["failed"] == sum(r["decision"] == "failed" for r in inb)
                assert b["cycle_p50"] == _pct([r["duration_s"] for r in inb], 50)
            day = await timeseries(s, make_filters(), "day")
            assert [b["count"] for b in day["data"]] == [
                n for _, n in sorted(Counter(r["started_at"].date() for r in rows).items())
            ]

            # Confusion against the truth.
            cf = await confusion(s, make_filters())
            truthful = [r for r in rows if r["truth"] is not None]
            assert cf["count"] == len(truthful)
            exp_cells = Counter(
                (r["truth"]["name"], r["model_name"] if r["decision"] == "recognized" else r["decision"])
                for r in truthful
            )  # fmt: skip
            for (t, lb), n in exp_cells.items():
                assert cf["matrix"][cf["truth"].index(t)][cf["labels"].index(lb)] == n
            assert cf["labels"][-2:] == ["unknown", "failed"]

            with pytest.raises(NotFound, match="no cell named 'cell-9'"):
                await summary(s, make_filters(cell="cell-9"))
            with pytest.raises(InvalidInput, match="minute buckets"):
                await timeseries(
                    s, make_filters(start=START, end=START + timedelta(days=30)), "minute"
                )
        exported = [r async for r in export_rows(db, make_filters())]
        assert [r["id"] for r in exported] == sorted(r["id"] for r in exported)
        assert len(exported) == N
        return {"summary": got, "filtered": got_f, "ts": ts, "confusion": cf}
    finally:
        await db.dispose()


def test_reports_sqlite_match_python(tmp_path) -> None:
    url = f"sqlite+aiosqlite:///{tmp_path / 'r.db'}"
    upgrade(url)
    asyncio.run(_check_engine(url))


def test_reports_postgres_match_python_and_sqlite(postgres_url, tmp_path) -> None:
    url = f"sqlite+aiosqlite:///{tmp_path / 'r.db'}"
    upgrade(url)
    lite = asyncio.run(_check_engine(url))
    pg = asyncio.run(_check_engine(postgres_url))
    for part in lite:
        for k in lite[part]:
            assert pg[part][k] == lite[part][k], (part, k, pg[part][k], lite[part][k])


def test_nearest_rank() -> None:
    assert [nearest_rank(50, n) for n in (1, 2, 3, 4)] == [1, 1, 2, 2]
    assert nearest_rank(95, 100) == 95 and nearest_rank(99, 101) == 100
    with pytest.raises(ValueError, match="p=0"):
        nearest_rank(0, 3)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"start": "yesterday"}, "from must be an ISO-8601 date-time, got 'yesterday'"),
        ({"start": "2026-02-01", "end": "2026-01-01"}, "is after to"),
        ({"start": "2024-01-01", "end": "2026-01-01"}, "longer than 400 days"),
        ({"end": "1900-01-01"}, "to must be within the years"),
        ({"cell": "Cell One"}, "cell must be a cell name"),
        ({"model": "x" * 65}, "model must be a model name"),
        ({"decision": "ok"}, "decision must be one of recognized, unknown, failed, got 'ok'"),
        ({"policy": "all"}, "policy must be one of"),
    ],
)
def test_bad_filters_are_refused(kwargs: dict[str, str], message: str) -> None:
    with pytest.raises(InvalidInput, match=message):
        make_filters(**kwargs)  # type: ignore[arg-type]


def test_times_without_offset_are_utc() -> None:
    f = make_filters(start="2026-09-01T10:00", end="2026-09-01T12:00+02:00")
    assert f.start == datetime(2026, 9, 1, 10, tzinfo=UTC)
    assert f.end == datetime(2026, 9, 1, 10, tzinfo=UTC)
