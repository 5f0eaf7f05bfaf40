"""Image retention: the ``failures`` setting, whole-or-nothing writes, pruning, the automatic
prune of the runtime, and the 3D scene recorder with a real viser server."""

from __future__ import annotations

import asyncio
from datetime import UTC, datetime, timedelta

import pytest
from sqlalchemy import func, select

from backend.db.models import Inspection, InspectionImage, InspectionScene
from backend.db.session import Database
from backend.inspection.results import InspectionRecord, ViewRecord, store
from backend.reports import SceneRecorder, keeps_images, prune, storage_used
from backend.reports.retention import PruneResult
from benchmarks.reports_data import ensure_cells
from tests.utils.factories import free_port, make_settings, migrate
from tests.utils.scenes import decode_scene
from vision.errors import InvalidInput

JPEG = b"\xff\xd8" + bytes(998)


def _rec(decision: str, t: datetime, n_views: int = 2, jpeg: bytes | None = JPEG) -> InspectionRecord:  # fmt: skip
    return InspectionRecord(
        started_at=t, finished_at=t, decision=decision, reason="r", policy="two-views",
        model_name="m" if decision == "recognized" else None,
        views=tuple(ViewRecord(v + 1, jpeg, {}) for v in range(n_views)),  # type: ignore[arg-type]
    )  # fmt: skip


async def _counts(db: Database) -> tuple[int, int, int]:
    async with db.session() as s:
        return (
            int(await s.scalar(select(func.count(Inspection.id))) or 0),
            int(await s.scalar(select(func.count(InspectionImage.id))) or 0),
            int(await s.scalar(select(func.count(InspectionScene.id))) or 0),
        )


@pytest.fixture
def db_url(tmp_path) -> str:
    s = make_settings(tmp_path)
    migrate(s)
    return s.database_url


def test_keeps_images() -> None:
    assert keeps_images("all", "recognized") and keeps_images("failures", "unknown")
    assert keeps_images("failures", "failed") and not keeps_images("failures", "recognized")
    with pytest.raises(InvalidInput, match="'some'"):
        keeps_images("some", "failed")


def test_failures_retention_stores_rows_but_not_the_images_of_recognised_ones(db_url) -> None:
    async def run() -> tuple[int, int, int]:
        db = Database(db_url)
        try:
            (cid,) = await ensure_cells(db, ("cell-1",))
            t = datetime.now(UTC)
            for d in ("recognized", "unknown", "failed"):
                await store(db, cid, _rec(d, t), retention="failures", scene=b"s" * 100)
            return await _counts(db)
        finally:
            await db.dispose()

    assert asyncio.run(run()) == (3, 4, 2)


def test_a_failure_mid_write_leaves_no_row(db_url) -> None:
    """The second image cannot be written (NOT NULL): no inspection, image or scene stays."""

    async def run() -> tuple[int, int, int]:
        db = Database(db_url)
        try:
            (cid,) = await ensure_cells(db, ("cell-1",))
            rec = _rec("unknown", datetime.now(UTC), 1)
            bad = InspectionRecord(**{**rec.__dict__, "views": (*rec.views, ViewRecord(2, None, {}))})  # type: ignore[arg-type]  # fmt: skip
            with pytest.raises(Exception, match=r"(?i)null"):
                await store(db, cid, bad, scene=b"x" * 10)
            return await _counts(db)
        finally:
            await db.dispose()

    assert asyncio.run(run()) == (0, 0, 0)


def test_prune_by_age_and_size(db_url) -> None:
    async def run() -> list[object]:
        db = Database(db_url)
        try:
            (cid,) = await ensure_cells(db, ("cell-1",))
            now = datetime.now(UTC)
            for age in (40, 20, 10, 1):  # days
                await store(db, cid, _rec("failed", now - timedelta(days=age)), scene=b"s" * 24)
            got: list[object] = []
            got.append(await prune(db, older_than_days=30))
            got.append(await prune(db, older_than_days=30))  # nothing left that old
            async with db.session() as s:
                got.append(await storage_used(s))
            got.append(await prune(db, max_bytes=2 * 2024))  # the two newest stay
            got.append(await prune(db, max_bytes=2 * 2024))
            got.append(await _counts(db))
            with pytest.raises(InvalidInput, match="older_than_days"):
                await prune(db, older_than_days=-1)
            return got
        finally:
            await db.dispose()

    a, b, used, c, d, counts = asyncio.run(run())
    assert a == PruneResult(2, 2024, 1) and b == PruneResult()
    assert used == {"images": 6, "image_bytes": 6000, "scenes": 3, "scene_bytes": 72, "bytes": 6072}
    assert c == PruneResult(2, 2024, 1) and d == PruneResult()
    assert counts == (4, 4, 2)


def test_runtime_prunes_at_start_up(tmp_path) -> None:
    from backend.runtime import CellRuntime

    settings = make_settings(tmp_path, image_max_age_days=5)
    migrate(settings)

    async def run() -> tuple[int, int, int]:
        db = Database(settings.database_url)
        (cid,) = await ensure_cells(db, (settings.cell_name,))
        await store(db, cid, _rec("failed", datetime.now(UTC) - timedelta(days=9)))
        await store(db, cid, _rec("failed", datetime.now(UTC)))
        await db.dispose()
        async with CellRuntime(settings) as rt:
            for _ in range(100):
                counts = await _counts(rt.database)
                if counts[1] == 2:
                    break
                await asyncio.sleep(0.05)
            return counts

    assert asyncio.run(run()) == (2, 2, 0)


def test_settings_refuse_bad_retention(tmp_path) -> None:
    from pydantic import ValidationError

    with pytest.raises(ValidationError, match="image_retention"):
        make_settings(tmp_path, image_retention="some")
    with pytest.raises(ValidationError, match="image_max_age_days"):
        make_settings(tmp_path, image_max_age_days=0)
    with pytest.raises(ValidationError, match="image_max_bytes"):
        make_settings(tmp_path, image_max_bytes=10)


def test_scene_recorder_records_a_viser_scene() -> None:
    import viser

    async def run() -> tuple[bytes | None, bytes | None, bool]:
        server = viser.ViserServer(host="127.0.0.1", port=free_port(), verbose=False)
        try:
            server.scene.add_box("/before", dimensions=(0.1, 0.1, 0.1))
            rec = SceneRecorder(server)
            assert rec.recording
            await asyncio.sleep(0.12)
            server.scene.add_icosphere("/during", radius=0.05)
            await asyncio.sleep(0.12)
            data = await rec.finish()
            tiny = SceneRecorder(server, max_bytes=10)
            small = await tiny.finish()
            none = await SceneRecorder(None).finish()
            return data, small, none is None
        finally:
            server.stop()

    data, small, none = asyncio.run(run())
    assert data is not None and len(data) > 100
    meta = decode_scene(data)
    names = [m.get("name") for _, m in meta["messages"]]
    assert "/before" in names and "/during" in names  # the snapshot and a message sent meanwhile
    t_during = next(t for t, m in meta["messages"] if m.get("name") == "/during")
    assert 0.05 < t_during <= meta["durationSeconds"] < 5.0  # real time between messages
    assert small is None and none


def test_scene_recorder_stops_at_its_time_cap() -> None:
    import viser

    async def run() -> bytes | None:
        server = viser.ViserServer(host="127.0.0.1", port=free_port(), verbose=False)
        try:
            rec = SceneRecorder(server, max_s=0.1)
            await asyncio.sleep(0.4)
            assert not rec.recording
            server.scene.add_box("/late", dimensions=(0.1, 0.1, 0.1))
            return await rec.finish()
        finally:
            server.stop()

    data = asyncio.run(run())
    assert data is not None
    meta = decode_scene(data)
    assert "/late" not in [m.get("name") for _, m in meta["messages"]]
    assert meta["durationSeconds"] == pytest.approx(0.1)
