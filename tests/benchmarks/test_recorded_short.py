"""``benchmarks/recorded.py`` in its short form: COIL-20 trained through the product at 20
degree spacing, a subsample of queries through the endpoint and through the library, the
same queries replayed by a recorded cell's inspection run, one table and one JSON line."""

from __future__ import annotations

import json

import pytest

from benchmarks import recorded
from benchmarks.recognition_data import coil_folder


def test_recorded_benchmark_short(data_dir, capsys) -> None:
    try:
        coil_folder(data_dir)
    except FileNotFoundError as exc:
        pytest.skip(str(exc))
    recorded.main(["--short", "--json", "--data-dir", str(data_dir)])
    out = capsys.readouterr()
    lines = out.out.strip().splitlines()
    res = json.loads(lines[-1])
    assert "known top-1" in out.out and "endpoint / library" in out.out
    assert "round 1: endpoint and library" in out.err  # progress shown
    assert "recorded cell: inspecting" in out.err
    e, lib = res["endpoint"], res["library"]
    assert res["trained_views"] == 180 and e["known"] == lib["known"] == 60
    # One row per image of each pass: one image per request, then the CLI's batches.
    assert e["unknown"] == 15 and res["stored_rows"] == 2 * (e["known"] + e["unknown"])
    assert res["threshold"] >= 0.03 and res["threshold_runs"] >= 1
    # The endpoint decides as the library does on the same images and thresholds (up to
    # the approximate search's randomness, which another part of the product removes).
    assert abs(e["top1"] - lib["top1"]) <= 2 / e["known"]
    assert abs(e["false_accept_count"] - lib["false_accept_count"]) <= 1
    assert e["top1"] >= 0.9
    assert res["endpoint_ms_per_image"] > 0 and res["library_ms_per_image"] > 0
    assert res["time_ratios"] == [res["time_ratio"]] and res["store_ms_per_image"] > 0
    # The CLI's way: batches of its size, the same answers as one image per request.
    assert res["cli_batch"] == 8 and res["cli_answers_identical"] is True
    assert res["cli_time_ratios"] == [res["cli_time_ratio"]] and res["cli_ms_per_image"] > 0
    assert "8 images per request (the CLI's way)" in out.err and "CLI / library" in out.out
    assert len(res["load_average"]["before"]) == 3
    # The recorded cell: every image of the recording inspected once, in its order, and
    # decided as the endpoint decided it.
    cell = res["recorded_cell"]
    assert cell["inspections"] == e["known"] + e["unknown"] and cell["failed"] == 0
    assert cell["known"] == 60 and cell["unknown"] == 15
    assert cell["top1"] >= 0.9 and cell["false_accept_count"] <= 1
    assert cell["same_as_endpoint"] >= cell["inspections"] - 2
    assert "recorded cell:" in out.out
