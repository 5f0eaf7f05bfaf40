"""The reporting API: shapes, roles, validation errors, the streamed exports against the
database, storage and pruning (engineer), and the scene route."""

from __future__ import annotations

import asyncio
import csv
import io
import json
from datetime import UTC, datetime
from typing import Any

import pytest
from sqlalchemy import func, select

from backend.db.models import Inspection, InspectionImage
from backend.db.session import Database
from backend.inspection.results import InspectionRecord, ViewRecord, store
from backend.reports.export import FIELDS
from benchmarks.reports_data import ensure_cells, generate_rows, insert_rows

N = 300


async def _fill(url: str) -> None:
    db = Database(url)
    try:
        ids = await ensure_cells(db)
        rows = generate_rows(N, ids, seed=3, start=datetime(2026, 9, 1, tzinfo=UTC), period_s=120)
        await insert_rows(db, rows)
    finally:
        await db.dispose()


@pytest.fixture
def filled(settings) -> Any:
    asyncio.run(_fill(settings.database_url))
    return settings


def test_summary_timeseries_confusion_shapes(filled, client, headers) -> None:
    r = client.get("/api/reports/summary", headers=headers["viewer"])
    assert r.status_code == 200, r.text
    s = r.json()
    assert s["count"] == N and sum(s["by_decision"].values()) == N
    assert set(s["cycle_s"]) == {"p50", "p95", "p99", "mean", "max"}
    assert 0.0 <= s["yield"] <= 1.0 and s["per_model"] and s["stages"]["move"]["p95"] > 0
    r = client.get("/api/reports/timeseries?bucket=day&cell=cell-1", headers=headers["viewer"])
    assert r.status_code == 200, r.text
    ts = r.json()
    assert ts["bucket"] == "day" and ts["data"][0]["t"].endswith("+00:00")
    assert {"t", "count", "recognized", "unknown", "failed", "cycle_p50"} <= set(ts["data"][0])
    r = client.get("/api/reports/confusion?policy=naive", headers=headers["viewer"])
    assert r.status_code == 200, r.text
    cf = r.json()
    assert len(cf["matrix"]) == len(cf["truth"]) and len(cf["matrix"][0]) == len(cf["labels"])


@pytest.mark.parametrize(
    ("query", "status", "needle"),
    [
        ("from=notatime", 422, "from: must be an ISO-8601 date-time with a zone"),
        ("from=2026-09-02", 422, "from: must be an ISO-8601 date-time with a zone"),
        ("from=2026-09-02T00:00:00Z&to=2026-09-01T00:00:00Z", 422, "is after to"),
        ("decision=ok", 422, "decision"),
        ("policy=nope", 422, "policy"),
        ("cell=Bad%20Cell", 422, "cell must be a cell name"),
        ("cell=cell-9", 404, "no cell named 'cell-9'"),
        ("model=" + "m" * 65, 422, "model"),
    ],
)
def test_bad_filters_answer_4xx(filled, client, headers, query: str, status: int, needle: str) -> None:  # fmt: skip
    for route in ("summary", "timeseries", "confusion", "export.csv", "export.jsonl"):
        r = client.get(f"/api/reports/{route}?{query}", headers=headers["viewer"])
        assert r.status_code == status, (route, r.text)
        body = r.json()
        assert set(body) == {"error", "detail"} and needle in body["detail"], body


def test_bad_bucket_and_too_many_buckets(filled, client, headers) -> None:
    r = client.get("/api/reports/timeseries?bucket=week", headers=headers["viewer"])
    assert r.status_code == 422 and "bucket" in r.json()["detail"]
    r = client.get("/api/reports/timeseries?bucket=minute&from=2026-01-01T00:00Z&to=2026-03-01T00:00Z",
                   headers=headers["viewer"])  # fmt: skip
    assert r.status_code == 422 and "minute buckets" in r.json()["detail"]


def test_reports_need_a_token(filled, client) -> None:
    for path in ("summary", "timeseries", "confusion", "export.csv", "export.jsonl", "storage"):
        r = client.get(f"/api/reports/{path}")
        assert r.status_code == 401, path


async def _db_rows(url: str) -> dict[int, Any]:
    db = Database(url)
    try:
        async with db.session() as s:
            rows = (
                await s.scalars(select(Inspection).where(Inspection.policy == "best-next"))
            ).all()
            return {r.id: r for r in rows}
    finally:
        await db.dispose()


def test_csv_and_jsonl_exports_match_the_database(filled, client, headers) -> None:
    r = client.get("/api/reports/export.csv?policy=best-next", headers=headers["viewer"])
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/csv")
    rows = list(csv.DictReader(io.StringIO(r.text)))
    assert tuple(csv.reader(io.StringIO(r.text)).__next__()) == FIELDS
    db = asyncio.run(_db_rows(filled.database_url))
    assert len(rows) == len(db) > 0
    for row in rows:
        d = db[int(row["id"])]
        assert row["decision"] == d.decision.value and row["policy"] == "best-next"
        assert row["model"] == (d.model_name or "")
        assert (float(row["score"]) if row["score"] else None) == d.score
        assert float(row["duration_s"]) == d.duration_s
        assert datetime.fromisoformat(row["started_at"]) == d.started_at
        assert int(row["views"]) == len(d.viewpoints_visited)
        assert row["truth_name"] == ((d.truth or {}).get("name") or "")
        if d.pose:
            assert float(row["x_mm"]) == pytest.approx(d.pose["position_m"][0] * 1e3, abs=1e-3)
    r = client.get("/api/reports/export.jsonl?policy=best-next", headers=headers["viewer"])
    assert r.status_code == 200
    lines = [json.loads(x) for x in r.text.splitlines()]
    assert [x["id"] for x in lines] == [int(x["id"]) for x in rows]
    assert set(lines[0]) == set(FIELDS)


async def _store_some(url: str, cell_name: str) -> None:
    db = Database(url)
    try:
        (cid,) = await ensure_cells(db, (cell_name,))
        t = datetime(2026, 1, 1, tzinfo=UTC)
        for i, dec in enumerate(("recognized", "unknown", "failed")):
            rec = InspectionRecord(started_at=t, finished_at=t, decision=dec, reason="test",
                                   policy="two-views", model_name="wheel-a" if i == 0 else None,
                                   views=(ViewRecord(1, b"\xff\xd8" + bytes(1000), {}),
                                          ViewRecord(2, b"\xff\xd8" + bytes(500), {})))  # fmt: skip
            await store(db, cid, rec, scene=b"scene" * 10)
    finally:
        await db.dispose()


def test_storage_and_prune(settings, client, headers) -> None:
    asyncio.run(_store_some(settings.database_url, settings.cell_name))
    r = client.get("/api/reports/storage", headers=headers["viewer"])
    assert r.status_code == 200, r.text
    st = r.json()
    assert st["images"] == 6 and st["image_bytes"] == 3 * 1504 and st["scenes"] == 3
    assert st["bytes"] == 3 * 1504 + 3 * 50 and st["retention"] == "all"
    r = client.post("/api/reports/storage/prune", json={"older_than_days": 1},
                    headers=headers["operator"])  # fmt: skip
    assert r.status_code == 403
    r = client.post("/api/reports/storage/prune", json={"older_than_days": -1},
                    headers=headers["engineer"])  # fmt: skip
    assert r.status_code == 422
    r = client.post(
        "/api/reports/storage/prune", json={"max_bytes": "1"}, headers=headers["engineer"]
    )
    assert r.status_code == 422
    # The size cap: the oldest inspection's images and scene go first, all together.
    r = client.post("/api/reports/storage/prune", json={"max_bytes": 2 * 1554},
                    headers=headers["engineer"])  # fmt: skip
    assert r.status_code == 200, r.text
    assert r.json() == {"deleted_images": 2, "freed_bytes": 1554, "deleted_scenes": 1}
    r = client.post("/api/reports/storage/prune", json={"older_than_days": 0},
                    headers=headers["engineer"])  # fmt: skip
    assert r.json() == {"deleted_images": 4, "freed_bytes": 2 * 1554, "deleted_scenes": 2}
    st = client.get("/api/reports/storage", headers=headers["viewer"]).json()
    assert st["images"] == 0 and st["bytes"] == 0
    # The rows stay: reports keep counting them.
    assert client.get("/api/reports/summary", headers=headers["viewer"]).json()["count"] == 3


def test_scene_route(settings, client, headers) -> None:
    asyncio.run(_store_some(settings.database_url, settings.cell_name))
    ids = client.get("/api/inspections", headers=headers["viewer"]).json()["data"]
    iid = ids[0]["id"]
    r = client.get(f"/api/inspections/{iid}/scene", headers=headers["viewer"])
    assert r.status_code == 200 and r.content == b"scene" * 10
    assert r.headers["content-type"] == "application/octet-stream"
    r = client.get("/api/inspections/999999/scene", headers=headers["viewer"])
    assert r.status_code == 404 and "no recorded 3D scene" in r.json()["detail"]
    r = client.get(f"/api/inspections/{iid}/scene")
    assert r.status_code == 401


async def _count(url: str) -> tuple[int, int]:
    db = Database(url)
    try:
        async with db.session() as s:
            n = int(await s.scalar(select(func.count(Inspection.id))) or 0)
            m = int(await s.scalar(select(func.count(InspectionImage.id))) or 0)
            return n, m
    finally:
        await db.dispose()
