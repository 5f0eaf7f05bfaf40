"""In-progress markers (issue 16, part 1): written before an inspection, removed in the
result's transaction; left by a killed process, they become one ``failed`` row marked
interrupted at start-up (once, never twice); a store retried after a commit whose answer
was lost does not write a second row; database errors are told from bugs."""

from __future__ import annotations

import sqlite3
import threading
from datetime import timedelta

import pytest
from sqlalchemy import func, select
from sqlalchemy.exc import OperationalError

from backend.db.models import Inspection, InspectionInProgress
from backend.db.session import Database
from backend.db.types import utcnow
from backend.inspection import recovery, results
from backend.runtime import ensure_cell_row
from tests.utils.factories import make_settings, migrate


@pytest.fixture
def url(tmp_path):
    settings = make_settings(tmp_path)
    migrate(settings)
    return settings.database_url


@pytest.fixture
async def db(url):
    d = Database(url, busy_timeout_s=0.2)
    yield d
    await d.dispose()


def _rec(**kw):
    t = utcnow()
    base = dict(started_at=t, finished_at=t + timedelta(seconds=1), decision="unknown",
                reason="no model passed", policy="two-views", viewpoints=(1,))  # fmt: skip
    base.update(kw)
    return results.InspectionRecord(**base)


async def _count(db, model):
    async with db.session() as s:
        return int(await s.scalar(select(func.count(model.id))) or 0)


async def test_store_removes_the_marker_in_its_transaction(db):
    cell = await ensure_cell_row(db, "cell-1")
    marker = await recovery.begin(db, cell, "two-views")
    assert await _count(db, InspectionInProgress) == 1
    iid = await results.store(db, cell, _rec(), marker_id=marker)
    assert await _count(db, InspectionInProgress) == 0 and await _count(db, Inspection) == 1
    # the same store retried (its first answer lost): no second row
    again = await results.store(db, cell, _rec(started_at=(await _first(db)).started_at),
                                marker_id=marker)  # fmt: skip
    assert again == iid and await _count(db, Inspection) == 1


async def _first(db):
    async with db.session() as s:
        return await s.scalar(select(Inspection).order_by(Inspection.id))


async def test_a_marker_left_behind_becomes_one_interrupted_row(db):
    cell = await ensure_cell_row(db, "cell-1")
    async with db.session() as s:  # as a killed process leaves it: another pid, gone
        s.add(InspectionInProgress(cell_id=cell, policy="naive", owner="elsewhere:999999"))
    other = await ensure_cell_row(db, "cell-2")
    await recovery.begin(db, other, "naive")  # another cell's marker is not ours
    ids = await recovery.mark_interrupted(db, cell)
    assert len(ids) == 1
    row = await _first(db)
    assert row.decision.value == "failed" and row.reason.startswith("interrupted:")
    assert row.finished_at is not None and row.policy == "naive"
    assert await recovery.mark_interrupted(db, cell) == []  # once, never twice
    assert await _count(db, InspectionInProgress) == 1  # cell-2's stays


async def test_a_live_process_marker_is_not_interrupted(db):
    import os
    import socket

    cell = await ensure_cell_row(db, "cell-1")
    async with db.session() as s:  # our parent runs: its inspection is not interrupted
        s.add(InspectionInProgress(cell_id=cell, policy="naive",
                                   owner=f"{socket.gethostname()[:100]}:{os.getppid()}"))  # fmt: skip
    assert await recovery.mark_interrupted(db, cell) == []


async def test_a_locked_database_is_a_database_error_and_retry_waits_it_out(db, tmp_path):
    cell = await ensure_cell_row(db, "cell-1")
    path = db.url.split(":///", 1)[1]
    release = threading.Event()
    locked = threading.Event()

    def hold():
        con = sqlite3.connect(path, isolation_level=None)
        con.execute("BEGIN EXCLUSIVE")
        locked.set()
        release.wait(10)
        con.execute("ROLLBACK")
        con.close()

    t = threading.Thread(target=hold)
    t.start()
    locked.wait(5)
    with pytest.raises(OperationalError) as info:
        await recovery.begin(db, cell, "naive")
    assert recovery.is_database_error(info.value)
    waits: list[str] = []
    import asyncio

    asyncio.get_running_loop().call_later(0.6, release.set)
    marker = await recovery.retry_database(
        "starting", lambda: recovery.begin(db, cell, "naive"), on_wait=waits.append
    )
    t.join()
    assert marker >= 1 and waits and "database unavailable" in waits[0]
    assert not recovery.is_database_error(ValueError("a bug"))
    with pytest.raises(ValueError):
        await recovery.retry_database("x", _raise_bug)


async def _raise_bug():
    raise ValueError("a bug is not retried")
