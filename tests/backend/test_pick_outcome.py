"""Where the object went, stored with the inspection and shown everywhere: the pick's outcome
(:func:`backend.inspection.results.pick_outcome`) in ``GET /api/inspections[/{id}]`` and in
the CSV export's last columns; and a model's height entered in millimetres (the console's
and the CLI's unit) through ``/api/models``."""

from __future__ import annotations

import asyncio
import csv
import io
import os
import subprocess
import sys
from datetime import UTC, datetime, timedelta

import pytest

from backend.db.session import Database
from backend.inspection import results
from backend.inspection.results import pick_outcome
from backend.reports.export import FIELDS
from tests.utils.factories import TEST_SECRET


@pytest.mark.parametrize(
    ("pick", "decision", "outcome", "bin_", "text"),
    [
        (None, "failed", "not_sorted", None, "not sorted"),
        ({"sorted": True, "ok": True, "bin": "bin-gear-housing", "reject": False}, "recognized",
         "placed", "bin-gear-housing", "placed in bin-gear-housing"),
        ({"sorted": True, "ok": True, "bin": "reject", "reject": True}, "unknown",
         "rejected", "reject", "rejected into reject: not a taught model"),
        ({"sorted": True, "ok": True, "bin": "reject", "reject": True,
          "how": "height 100 mm measured: guarded descent; no bin takes part 'x': rejected"},
         "recognized", "rejected", "reject", "rejected into reject: no bin takes part 'x': rejected"),
        ({"sorted": True, "ok": False, "bin": "bin-valve-block", "reason": "cannot pick: out of reach"},
         "recognized", "not_placed", "bin-valve-block",
         "not placed in bin-valve-block: cannot pick: out of reach"),
        ({"sorted": False, "ok": True, "stage": "approach"}, "recognized", "approach", None,
         "sorting off: moved to the approach pose"),
        ({"sorted": False, "ok": False, "reason": "not picked: no pose"}, "recognized",
         "not_picked", None, "not picked: not picked: no pose"),
        # rows stored before the "reject" key: the reject bin is known by its name
        ({"sorted": True, "ok": True, "bin": "reject"}, "failed", "rejected", "reject",
         "rejected into reject: the inspection failed"),
    ],
)  # fmt: skip
def test_pick_outcome_says_where_the_object_went(pick, decision, outcome, bin_, text):
    got = pick_outcome(pick, decision)
    assert got == {"outcome": outcome, "bin": bin_, "text": text}
    assert got["outcome"] in results.PICK_OUTCOMES


def _store(settings, pick, decision="recognized", model="gear-housing"):
    async def run() -> int:
        db = Database(settings.database_url)
        try:
            from sqlalchemy import select

            from backend.db.models import Cell

            async with db.session() as s:
                cell_id = await s.scalar(select(Cell.id).limit(1))
            t = datetime.now(UTC)
            rec = results.InspectionRecord(
                started_at=t, finished_at=t + timedelta(seconds=2), decision=decision,
                reason="test", policy="two-views", model_name=model, score=0.8,
                viewpoints=(1,), durations={"pick": 1.5}, pick=pick,
            )  # fmt: skip
            return await results.store(db, cell_id, rec)
        finally:
            await db.dispose()

    return asyncio.run(run())


def test_the_bin_is_in_the_rows_and_the_csv(client, headers, settings):
    placed = {"sorted": True, "ok": True, "bin": "bin-gear-housing", "reject": False,
              "stage": "release", "reason": "done"}  # fmt: skip
    failed = {"sorted": True, "ok": False, "bin": "bin-gear-housing", "reject": False,
              "reason": "cannot pick: no roll clears the obstacles"}  # fmt: skip
    a = _store(settings, placed)
    b = _store(settings, failed)
    c = _store(settings, None, decision="failed", model=None)
    op = headers["operator"]
    rows = {r["id"]: r for r in client.get("/api/inspections", headers=op).json()["data"]}
    assert rows[a]["pick_outcome"]["outcome"] == "placed"
    assert rows[b]["pick_outcome"]["outcome"] == "not_placed"
    assert "no roll clears" in rows[b]["pick_outcome"]["text"]
    assert rows[c]["pick_outcome"]["outcome"] == "not_sorted"
    one = client.get(f"/api/inspections/{a}", headers=op).json()
    assert one["pick_outcome"]["bin"] == "bin-gear-housing"
    r = client.get("/api/reports/export.csv", headers=op)
    assert r.status_code == 200
    table = list(csv.reader(io.StringIO(r.text)))
    assert tuple(table[0]) == FIELDS and table[0][16:20] == ["bin", "pick", "pick_detail", "source"]
    assert table[0][:16] == ["id", "cell", "started_at", "finished_at", "decision", "model",
                             "score", "policy", "views", "duration_s", "reason", "x_mm", "y_mm",
                             "yaw_deg", "truth_name", "viewpoints"]  # fmt: skip
    by_id = {int(row[0]): dict(zip(table[0], row, strict=True)) for row in table[1:]}
    assert (by_id[a]["bin"], by_id[a]["pick"]) == ("bin-gear-housing", "placed")
    assert by_id[b]["pick"] == "not_placed" and "no roll clears" in by_id[b]["pick_detail"]
    assert (by_id[c]["bin"], by_id[c]["pick"]) == ("", "not_sorted")
    r = client.get("/api/reports/export.jsonl", headers=op)
    assert any('"pick":"placed"' in line for line in r.text.splitlines())


def test_height_in_millimetres_through_rest(client, headers):
    eng = headers["engineer"]
    r = client.post("/api/models", json={"name": "valve-block", "kind": "3d", "height_mm": 162},
                    headers=eng)  # fmt: skip
    assert r.status_code == 201, r.text
    m = r.json()
    assert m["height_m"] == pytest.approx(0.162) and m["geometry_source"] == "entered"
    r = client.patch(f"/api/models/{m['id']}", json={"height_mm": 150.5}, headers=eng)
    assert r.status_code == 200 and r.json()["height_m"] == pytest.approx(0.1505)
    live = client.app.state.runtime.live_index.model_of_name("valve-block")
    assert live.height_m == pytest.approx(0.1505) and live.geometry_source == "entered"
    for body, needle in (({"height_mm": 0}, "height_mm"), ({"height_mm": 501}, "height_mm"),
                         ({"height_mm": "12"}, "height_mm"),
                         ({"height_mm": 100, "height_m": 0.1}, "not both")):  # fmt: skip
        r = client.patch(f"/api/models/{m['id']}", json=body, headers=eng)
        assert r.status_code == 422, (body, r.text)
        assert set(r.json()) == {"error", "detail"} and needle in r.json()["detail"], r.text
    assert client.get(f"/api/models/{m['id']}", headers=eng).json()["height_m"] == pytest.approx(
        0.1505
    )
    r = client.post("/api/models", json={"name": "x", "kind": "2d", "height_mm": -1}, headers=eng)
    assert r.status_code == 422
    assert client.get("/api/models", headers=eng).json()["count"] == 1


def test_models_add_takes_a_height_in_millimetres(settings):
    env = {**os.environ, "VISIONCELL_DATABASE_URL": settings.database_url,
           "VISIONCELL_SECRET_KEY": TEST_SECRET}  # fmt: skip
    run = [sys.executable, "-m", "backend.cli", "models", "add"]
    r = subprocess.run([*run, "pipe-flange", "--height-mm", "170"], capture_output=True,
                       text=True, env=env, timeout=120)  # fmt: skip
    assert r.returncode == 0, r.stderr
    bad = subprocess.run([*run, "other", "--height-mm", "900"], capture_output=True, text=True,
                         env=env, timeout=120)  # fmt: skip
    assert bad.returncode != 0 and "--height-mm" in bad.stdout + bad.stderr

    async def height() -> float | None:
        from backend.recognition.models import get_model_by_name

        db = Database(settings.database_url)
        try:
            async with db.session() as s:
                return (await get_model_by_name(s, "pipe-flange")).height_m
        finally:
            await db.dispose()

    assert asyncio.run(height()) == pytest.approx(0.17)
