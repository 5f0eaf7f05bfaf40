"""``benchmarks/reports.py`` in its short form: a few hundred rows on SQLite, one JSON line
with p50/p95 per route, with and without the report indexes."""

from __future__ import annotations

import json

from benchmarks import reports


def test_reports_benchmark_short(capsys, monkeypatch) -> None:
    monkeypatch.delenv("VISIONCELL_TEST_POSTGRES_URL", raising=False)
    assert reports.main(["--rows", "300", "--images", "40", "--repeats", "3", "--json"]) == 0
    last = capsys.readouterr().out.strip().splitlines()[-1]
    res = json.loads(last)
    assert res["rows"] == 300 and set(res["results"]) == {"sqlite"}
    routes = res["results"]["sqlite"]
    assert "summary (all)" in routes and "export first 1000 rows" in routes
    for r in routes.values():
        assert r["p95_ms"] >= r["p50_ms"] > 0 and r["base_p95_ms"] >= r["base_p50_ms"] > 0
