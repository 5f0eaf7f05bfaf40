"""A plant's cells share one database: another cell's inspection is a 404 here, and so is
its recorded 3D scene (the scene route filters by this process's cell like the row does)."""

from __future__ import annotations

import asyncio
from datetime import UTC, datetime

from backend.db.session import Database
from backend.inspection.results import InspectionRecord, store
from benchmarks.reports_data import ensure_cells


async def _store(url: str, cell_name: str) -> int:
    db = Database(url)
    try:
        (cid,) = await ensure_cells(db, (cell_name,))
        t = datetime(2026, 1, 1, tzinfo=UTC)
        rec = InspectionRecord(started_at=t, finished_at=t, decision="unknown", reason="test",
                               policy="two-views", model_name=None, views=())  # fmt: skip
        return int(await store(db, cid, rec, scene=b"other cell's scene"))
    finally:
        await db.dispose()


def test_another_cells_scene_is_a_404_like_its_row(settings, client, headers) -> None:
    other = asyncio.run(_store(settings.database_url, "cell-2"))
    mine = asyncio.run(_store(settings.database_url, settings.cell_name))
    v = headers["viewer"]
    r = client.get(f"/api/inspections/{other}", headers=v)
    assert r.status_code == 404, r.text
    r = client.get(f"/api/inspections/{other}/scene", headers=v)
    assert r.status_code == 404, r.text
    assert r.json() == {
        "error": "not_found",
        "detail": f"inspection {other} has no recorded 3D scene",
    }
    r = client.get(f"/api/inspections/{mine}/scene", headers=v)
    assert r.status_code == 200 and r.content == b"other cell's scene"
