"""``visioncell report``: the summary, the CSV and the plots; errors naming the bad value;
``report storage`` and ``report prune``."""

from __future__ import annotations

import asyncio
import csv
import os
import re
import subprocess
import sys
from datetime import UTC, datetime

from backend.db.migrate import upgrade
from backend.db.session import Database
from benchmarks.reports_data import ensure_cells, generate_rows, insert_rows
from tests.utils.factories import TEST_SECRET

N = 250


def _run(args: list[str], url: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "VISIONCELL_DATABASE_URL": url, "VISIONCELL_SECRET_KEY": TEST_SECRET,
           "COLUMNS": "200"}  # fmt: skip
    return subprocess.run([sys.executable, "-m", "backend.cli", "report", *args],
                          capture_output=True, text=True, env=env, timeout=120)  # fmt: skip


async def _fill(url: str) -> None:
    db = Database(url)
    try:
        ids = await ensure_cells(db)
        await insert_rows(db, generate_rows(N, ids, seed=5, start=datetime(2026, 9, 1, tzinfo=UTC)))
    finally:
        await db.dispose()


def test_report_summary_csv_and_plots(tmp_path) -> None:
    url = f"sqlite+aiosqlite:///{tmp_path / 'r.db'}"
    upgrade(url)
    asyncio.run(_fill(url))
    out_csv = tmp_path / "all.csv"
    r = _run(["--csv", str(out_csv), "--png", str(tmp_path / "plots"), "--bucket", "hour"], url)
    assert r.returncode == 0, r.stderr
    assert re.search(rf"inspections\s+│\s+{N} │", r.stdout), r.stdout
    assert "cycle time p95" in r.stdout and "Stages" in r.stdout and "Scores per model" in r.stdout
    rows = list(csv.DictReader(out_csv.open()))
    assert len(rows) == N and f"wrote {N} inspections" in r.stdout
    for name in ("throughput", "cycle_time", "scores", "confusion"):
        png = tmp_path / "plots" / f"{name}.png"
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
    one = _run(["--cell", "cell-2", "--decision", "failed"], url)
    assert one.returncode == 0, one.stderr
    assert "cell=cell-2" in one.stdout and "decision=failed" in one.stdout


def test_report_errors_name_the_bad_value(tmp_path) -> None:
    url = f"sqlite+aiosqlite:///{tmp_path / 'r.db'}"
    upgrade(url)
    for args, needle in (
        (["--from", "yesterday"], "--from must be an ISO-8601 date-time, got 'yesterday'"),
        (["--from", "2026-02-01", "--to", "2026-01-01"], "--from (2026-02-01T00:00:00+00:00) is after to"),
        (["--cell", "nope"], "no cell named 'nope'"),
        (["--decision", "ok"], "--decision must be one of recognized, unknown, failed, got 'ok'"),
        (["--bucket", "week"], "--bucket must be one of minute, hour, day, got 'week'"),
        (["--png", str(tmp_path / "r.db")], "--png must be a folder"),
        (["prune"], "nothing to prune by"),
        (["prune", "--older-than-days", "-3"], "--older-than-days must be in 0..3650, got -3"),
    ):  # fmt: skip
        r = _run(args, url)
        assert r.returncode == 2, (args, r.stdout, r.stderr)
        assert needle in " ".join(r.stderr.split()), (args, r.stderr)


def test_report_storage_and_prune(tmp_path) -> None:
    url = f"sqlite+aiosqlite:///{tmp_path / 'r.db'}"
    upgrade(url)
    r = _run(["storage"], url)
    assert r.returncode == 0 and "0 images (0 bytes)" in r.stdout, r.stderr
    r = _run(["prune", "--older-than-days", "30"], url)
    assert r.returncode == 0 and "deleted 0 images and 0 scenes, freed 0 bytes" in r.stdout
