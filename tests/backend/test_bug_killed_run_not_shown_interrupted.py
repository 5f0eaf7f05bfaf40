"""A job cut short by the process ending (kill -9) is listed by the next process as
``interrupted`` in ``/api/jobs`` (and ``/api/jobs/{id}``); an inspecting job names the
inspection rows its process left unfinished.  Markers are written in order, a start whose
end came first is never written, and a clean end leaves none behind."""

from __future__ import annotations

import asyncio
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest
from fastapi.testclient import TestClient
from sqlalchemy import select

from backend.app import create_app
from backend.db.models import InspectionInProgress, JobInProgress
from backend.db.session import Database
from backend.inspection import recovery
from backend.jobjournal import JobJournal, interrupted_jobs
from backend.jobs import JobManager, JobState
from backend.runtime import ensure_cell_row
from tests.utils.factories import make_settings, make_tokens, migrate

#: Bounds a hang only (a loaded machine is slow to start a server); never a speed claim.
HANG_S = 240.0


async def _markers(db: Database) -> list[JobInProgress]:
    async with db.session() as s:
        return list((await s.scalars(select(JobInProgress))).all())


@pytest.fixture
def url(tmp_path) -> str:
    settings = make_settings(tmp_path)
    migrate(settings)
    return settings.database_url


async def test_the_journal_keeps_one_marker_per_running_job(url) -> None:
    db = Database(url)
    try:
        cell = await ensure_cell_row(db, "cell-1")
        jobs = JobManager()
        journal = JobJournal(db, cell, owner="host-a:1")
        journal.start()
        jobs.add_listener(journal)
        release = asyncio.Event()

        async def long(_job):
            await release.wait()
            return {"ok": True}

        async def short(_job):
            return None

        running = jobs.start("teach", long, params={"model": "wheel"})
        for _ in range(20):  # short jobs: started and ended, maybe before being written
            await jobs.wait(jobs.start("move", short))
        async with asyncio.timeout(HANG_S):
            while [m.id for m in await _markers(db)] != [running.id]:
                await asyncio.sleep(0.01)
        (m,) = await _markers(db)
        assert (m.kind, m.params, m.owner, m.cell_id) == ("teach", {"model": "wheel"},
                                                           "host-a:1", cell)  # fmt: skip
        release.set()
        await jobs.wait(running)
        await journal.close()  # drains: the end is written
        assert await _markers(db) == []
    finally:
        await db.dispose()


async def test_markers_left_behind_become_interrupted_jobs_once(url) -> None:
    db = Database(url)
    try:
        cell = await ensure_cell_row(db, "cell-1")
        other = await ensure_cell_row(db, "cell-2")
        gone = "elsewhere:999999"
        async with db.session() as s:
            s.add(JobInProgress(id="run1", cell_id=cell, kind="inspection-run",
                                params={"policy": "naive"}, owner=gone))  # fmt: skip
            s.add(JobInProgress(id="mine", cell_id=other, kind="move", params={}, owner=gone))
            s.add(InspectionInProgress(cell_id=cell, policy="naive", owner=gone))
        owners: dict[int, str] = {}
        (iid,) = await recovery.mark_interrupted(db, cell, owners=owners)
        (job,) = await interrupted_jobs(db, cell, inspections=owners)
        assert job.id == "run1" and job.state is JobState.interrupted
        assert job.result == {"interrupted_inspections": [iid]}
        assert job.error["error"] == "interrupted" and gone in job.error["detail"]
        assert f"inspection(s) {iid} stored as failed" in job.error["detail"]
        assert job.public()["state"] == "interrupted" and job.finished_at is not None
        assert await interrupted_jobs(db, cell) == []  # reported once
        assert [m.id for m in await _markers(db)] == ["mine"]  # another cell's stays
    finally:
        await db.dispose()


def _serve_env(settings, port: int) -> dict[str, str]:
    return {
        **os.environ,
        "VISIONCELL_DATABASE_URL": settings.database_url,
        "VISIONCELL_HTTP_HOST": "127.0.0.1",
        "VISIONCELL_HTTP_PORT": str(port),
        "VISIONCELL_VIEW3D_ENABLED": "false",
        "VISIONCELL_DRIVER": "ideal",
        "VISIONCELL_CAMERA": "folder",
        "VISIONCELL_CAMERA_FOLDER": str(settings.camera_folder),
        "VISIONCELL_TIME_SCALE": "1",
        "VISIONCELL_SECRET_KEY": settings.secret_key.get_secret_value(),
        "VISIONCELL_VAR_DIR": str(settings.var_dir),
        "VISIONCELL_BOOTSTRAP_OPERATOR": "false",
    }


def test_a_job_killed_with_its_process_is_listed_as_interrupted(tmp_path: Path) -> None:
    settings = make_settings(tmp_path, time_scale=1.0)
    migrate(settings)
    tokens = make_tokens(settings)
    op = {"Authorization": f"Bearer {tokens['operator']}"}
    port = settings.http_port
    exe = Path(sys.executable).with_name("visioncell")
    log = open(tmp_path / "serve.log", "ab")  # noqa: SIM115 - closed below
    proc = subprocess.Popen([str(exe), "serve"], env=_serve_env(settings, port),
                            stdout=log, stderr=log)  # fmt: skip
    base = f"http://127.0.0.1:{port}/api"
    try:
        deadline = time.monotonic() + HANG_S
        with httpx.Client(timeout=30.0) as c:
            while True:
                assert proc.poll() is None, (tmp_path / "serve.log").read_text()[-2000:]
                assert time.monotonic() < deadline, "serve never answered /api/health"
                try:
                    if c.get(f"{base}/health").status_code == 200:
                        break
                except httpx.HTTPError:
                    pass
                time.sleep(0.1)
            # The slowest move the API takes, across the arm: it runs long after the kill.
            r = c.post(f"{base}/robot/move", headers=op,
                       json={"joints": [3.0, 1.2, -1.2, 0.5, 2.5], "speed": 0.01})  # fmt: skip
            assert r.status_code == 202, r.text
            job_id = r.json()["job"]["id"]
            db = Database(settings.database_url)
            try:
                while job_id not in [m.id for m in asyncio.run(_markers(db))]:
                    assert time.monotonic() < deadline, "the job's marker was never written"
                    time.sleep(0.05)
            finally:
                asyncio.run(db.dispose())
            assert c.get(f"{base}/jobs/{job_id}", headers=op).json()["job"]["state"] == "running"
        proc.send_signal(signal.SIGKILL)
        proc.wait(60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(60)
        log.close()
    with TestClient(create_app(settings)) as client:
        listed = client.get("/api/jobs", headers=op).json()["data"]
        (job,) = [j for j in listed if j["id"] == job_id]
        assert job["state"] == "interrupted" and job["kind"] == "move", job
        assert job["error"]["error"] == "interrupted"
        assert "ended while this job ran" in job["error"]["detail"]
        r = client.get(f"/api/jobs/{job_id}", headers=op)
        assert r.status_code == 200 and r.json()["job"]["state"] == "interrupted"
    with TestClient(create_app(settings)) as client:  # reported by one start-up only
        listed = client.get("/api/jobs", headers=op).json()["data"]
        assert job_id not in [j["id"] for j in listed]
