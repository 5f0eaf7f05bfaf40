"""Bug (fault campaign): a database that could not be written when an inspection stored its
result (SQLite locked by another connection, PostgreSQL restarting) raised out of the
inspection, so the continuous run ended and the result was lost.  Now the store is retried
with backoff until the database takes it, in the transaction that removes the in-progress
marker: one complete row, no marker left."""

from __future__ import annotations

import asyncio
import sqlite3
import threading
from types import SimpleNamespace

import pytest
from sqlalchemy import func, select

from backend.cell import EventBus
from backend.db.models import Inspection, InspectionInProgress
from backend.db.session import Database
from backend.db.types import utcnow
from backend.inspection import record, recovery
from backend.inspection.draft import InspectionDraft
from backend.inspection.options import InspectOptions
from backend.runtime import ensure_cell_row
from tests.utils.factories import make_settings, migrate


@pytest.fixture
def url(tmp_path):
    settings = make_settings(tmp_path)
    migrate(settings)
    return settings.database_url


async def test_a_result_waits_out_a_locked_database(url):
    db = Database(url, busy_timeout_s=0.1)
    try:
        cell = await ensure_cell_row(db, "cell-1")
        marker = await recovery.begin(db, cell, "two-views")
        release, locked = threading.Event(), threading.Event()

        def hold():
            con = sqlite3.connect(url.split(":///", 1)[1], isolation_level=None)
            con.execute("BEGIN EXCLUSIVE")
            locked.set()
            release.wait(10)
            con.execute("ROLLBACK")
            con.close()

        t = threading.Thread(target=hold)
        t.start()
        locked.wait(5)
        asyncio.get_running_loop().call_later(0.8, release.set)
        ctx = SimpleNamespace(
            rt=SimpleNamespace(
                database=db,
                cell_id=cell,
                bus=EventBus(),
                settings=SimpleNamespace(image_retention="all"),
            )
        )
        draft = InspectionDraft(decision="unknown", reason="no model passed its threshold",
                                score=0.1)  # fmt: skip
        out = await record.store(ctx, InspectOptions(), draft, utcnow(), marker=marker)
        t.join()
        assert out["decision"] == "unknown" and out["finished_at"] is not None
        async with db.session() as s:
            assert await s.scalar(select(func.count(Inspection.id))) == 1
            assert await s.scalar(select(func.count(InspectionInProgress.id))) == 0
    finally:
        await db.dispose()
