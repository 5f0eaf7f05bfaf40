"""Short soak (issue 16, part 5): 30 inspections in the simulated cell with resources
sampled after each; the run completes every one, and open files and database connections
do not grow after the warm-up (the long run in ``benchmarks/soak.py`` fits the slopes)."""

from __future__ import annotations

import argparse
import asyncio

import pytest

from benchmarks import soak

pytestmark = [pytest.mark.slow, pytest.mark.timeout(1800)]  # a campaign: minutes, not seconds


def test_thirty_inspections_leak_no_files_or_connections(tmp_path, monkeypatch):
    monkeypatch.setattr(soak, "OUT_DIR", tmp_path)
    args = argparse.Namespace(inspections=30, warmup=10, taught_every=6, policy="top-only",
                              time_scale=20.0, idle_s=1.0, max_wall_s=3600.0, docs=False)  # fmt: skip
    r = asyncio.run(soak.soak(args, lambda msg: None))
    assert r["inspections"] == 30 and sum(r["decisions"].values()) == 30
    files, conns = r["series"]["other_files"], r["series"]["db_connections"]
    # Compared as medians of five samples: each sample is taken as an inspection ends, when
    # an image file or a second pooled connection may be open for a moment (CI once saw
    # 27 -> 29 files between two single samples); a leak of one per inspection adds 20.
    # Files other than the database's own: a pooled connection that opens after the
    # warm-up brings the database file and its WAL (CI saw 25 -> 27 open files in all, a
    # step, not a slope); the connections are compared on their own below.
    assert files["late_median"] <= files["early_median"] + 1, (files, r["series"]["open_files"])
    assert conns["max"] <= 5 and conns["late_median"] <= conns["early_median"] + 1, conns
    assert r["series"]["rss_mb"]["max"] > 0 and (tmp_path / "soak.png").exists()
