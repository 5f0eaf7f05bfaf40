"""A SQLite ``-shm`` file shrunk outside VisionCell (truncated, written anew) while the pool
holds it mapped killed the process with SIGBUS in the driver's thread, without a log line.
The pool now checks the side files before every checkout: a shrunk ``-shm`` is grown back
(SQLite rebuilds its index from the WAL, nothing is lost) and a side file that cannot be
used is a 503 ``database_unavailable`` naming it, not a crash.

The crash itself is a signal, so the database work runs in a child process: a SIGBUS there
fails the test instead of ending pytest.  The same child without the guard (SQLAlchemy's
plain pool) shows the driver's crash, so the test can tell the two apart.
"""

from __future__ import annotations

import logging
import os
import signal
import subprocess
import sys
import textwrap

import pytest

from backend.db import sqlitefiles

CHILD = textwrap.dedent(
    """
    import asyncio, os, sys
    from sqlalchemy import event, text
    from sqlalchemy.ext.asyncio import create_async_engine
    from backend.db.session import Database, _sqlite_pragmas

    async def main(path, guarded):
        url = f"sqlite+aiosqlite:///{path}"
        db = Database(url)
        if not guarded:  # SQLAlchemy's own pool, as before the guard
            await db.dispose()
            db.engine = create_async_engine(url, pool_size=5, pool_pre_ping=True)
            event.listen(db.engine.sync_engine, "connect", _sqlite_pragmas)
            db.sessionmaker.configure(bind=db.engine)
        async with db.session() as s:
            await s.execute(text("create table t(x integer)"))
        total = 0
        for trial in range(5):
            for i in range(300):
                async with db.session() as s:
                    await s.execute(text("insert into t values (:x)"), {"x": i})
                total += 1
            os.truncate(path + "-shm", 0)  # as `: > cell.db-shm` would
            async with db.session() as s:
                n = await s.scalar(text("select count(*) from t"))
            print("trial", trial, n, total, flush=True)
            assert n == total, (n, total)
        await db.dispose()
        print("done", flush=True)

    asyncio.run(main(sys.argv[1], sys.argv[2] == "guarded"))
    """
)


def _child(tmp_path, mode: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", CHILD, str(tmp_path / f"{mode}.db"), mode],
        capture_output=True, text=True, timeout=600, cwd=os.getcwd(),
    )  # fmt: skip


def test_a_shrunk_shm_is_healed_and_nothing_is_lost(tmp_path) -> None:
    r = _child(tmp_path, "guarded")
    assert r.returncode == 0, (r.returncode, r.stdout[-2000:], r.stderr[-3000:])
    assert r.stdout.splitlines()[-1] == "done"
    assert "trial 4 1500 1500" in r.stdout
    assert r.stderr.count("was shrunk outside VisionCell") == 5, r.stderr[-3000:]


def test_without_the_guard_the_driver_dies_of_sigbus(tmp_path) -> None:
    r = _child(tmp_path, "plain")
    assert r.returncode == -signal.SIGBUS, (r.returncode, r.stdout[-500:], r.stderr[-500:])
    assert "done" not in r.stdout


def test_an_unusable_side_file_is_a_503_naming_it(settings, client, headers, monkeypatch,
                                                  caplog) -> None:  # fmt: skip
    path = settings.sqlite_path()
    assert client.get("/api/inspections", headers=headers["viewer"]).status_code == 200
    shm = f"{path}-shm"
    assert os.path.exists(shm)
    real = os.access
    monkeypatch.setattr(sqlitefiles.os, "access",
                        lambda p, mode: False if str(p) == shm else real(p, mode))  # fmt: skip
    caplog.set_level(logging.ERROR, logger="backend.db.sqlitefiles")
    for _ in range(3):
        r = client.get("/api/inspections?limit=7", headers=headers["viewer"])
        assert r.status_code == 503, r.text
        assert r.json()["error"] == "database_unavailable", r.json()
    msgs = [m.getMessage() for m in caplog.records if "not writable" in m.getMessage()]
    assert len(msgs) == 1 and shm in msgs[0]  # once per outage
    monkeypatch.setattr(sqlitefiles.os, "access", real)
    r = client.get("/api/inspections?limit=8", headers=headers["viewer"])
    assert r.status_code == 200, r.text


@pytest.mark.parametrize("wal_frames", [0, 5000, 20000])
def test_the_restored_size_covers_the_wal(tmp_path, wal_frames: int) -> None:
    wal = tmp_path / "x.db-wal"
    header = bytearray(32)
    header[8:12] = (4096).to_bytes(4, "big")
    wal.write_bytes(bytes(header))
    with open(wal, "r+b") as f:
        f.truncate(32 + wal_frames * (4096 + 24))
    size = sqlitefiles._needed_shm_bytes(str(wal), 0)
    assert size % sqlitefiles.REGION_BYTES == 0
    assert size >= (wal_frames // 4062 + 1) * sqlitefiles.REGION_BYTES
