"""CellRuntime: the one assembly (database at head, cell row, hardware, cell, view) and its
clean teardown, also when a later part fails to start."""

from __future__ import annotations

import socket

import pytest
from sqlalchemy import select

from backend.db.models import Cell as CellRow
from backend.runtime import CellRuntime, StartupError
from tests.utils.factories import make_settings, migrate


async def test_runtime_builds_the_cell_and_tears_it_down(settings):
    s = settings.model_copy(update={"cell_name": "press-4"})
    rt = CellRuntime(s)
    with pytest.raises(RuntimeError, match="not running"):
        _ = rt.cell
    async with rt:
        assert rt.running and rt.cell.name == "press-4" and rt.cell.db_id == rt.cell_id
        async with rt.database.session() as session:
            names = (await session.scalars(select(CellRow.name))).all()
        assert names == ["press-4"]
        driver = rt.cell.driver
        assert driver.state.connected
        job = rt.cell.home(speed=1.0)
        await rt.jobs.wait(job)
        assert job.state.value == "done"
        assert rt.sim is None and rt.view3d is None and rt.cell.world is None
    assert not rt.running and not driver.state.connected
    async with CellRuntime(s) as again:  # the row is found again, not duplicated
        assert again.cell_id == rt.cell_id


async def test_runtime_refuses_a_database_not_at_head(tmp_path):
    s = make_settings(tmp_path)  # never migrated
    with pytest.raises(StartupError, match="run `visioncell db upgrade`"):
        async with CellRuntime(s):
            pass


@pytest.fixture
def blocked_viser(tmp_path):
    """Migrated settings whose viser port is taken by another socket."""
    with socket.socket() as blocker:
        blocker.bind(("127.0.0.1", 0))
        blocker.listen()
        s = make_settings(tmp_path, viser_port=blocker.getsockname()[1])
        migrate(s)
        yield s


async def test_a_failing_view_leaves_nothing_running(blocked_viser):
    s = blocked_viser
    rt = CellRuntime(s, view3d=True)
    with pytest.raises(RuntimeError, match=f"viser port {s.viser_port}"):
        async with rt:
            pass
    assert not rt.running and rt.view3d is None
    async with CellRuntime(s) as ok:  # and it can start again (no view)
        assert ok.cell.driver.state.connected
