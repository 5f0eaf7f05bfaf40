"""The short mode of the E-STOP benchmark (``benchmarks/estop.py``): it runs every fault
condition with both paths and prints one JSON object last with every field (behaviour
only: the timing is the benchmark's business, not this test's)."""

from __future__ import annotations

import json

import pytest

from benchmarks import estop

pytestmark = pytest.mark.slow


def test_the_short_run_measures_every_condition(capsys):
    estop.main(["--short", "--json"])
    last = capsys.readouterr().out.strip().splitlines()[-1]
    res = json.loads(last)
    assert set(res) >= {"driver", "samples", "target_p99_ms", "conditions", "uploads",
                        "all_within_target", "all_latched"}  # fmt: skip
    assert list(res["conditions"]) == list(estop.CONDITIONS)
    for name, paths in res["conditions"].items():
        assert set(paths) == {"rest", "view3d"}, name
        for path, r in paths.items():
            assert set(r) == {"n", "p50_ms", "p99_ms", "max_ms", "status", "all_latched"}
            assert r["n"] == res["samples"] == 3, (name, path)
            assert r["status"] == {"200": 3}, (name, path, r["status"])
            assert r["all_latched"] is True, (name, path)
            assert 0 < r["p50_ms"] <= r["p99_ms"] <= r["max_ms"], (name, path, r)
    assert res["uploads"]["statuses"], "no upload ran during the busy-loop condition"
    assert res["all_latched"] is True


def test_bad_options_are_refused():
    for argv in (["--samples", "0"], ["--upload-mp", "nan"], ["--gap", "-1"],
                 ["--conditions", "nonsense"]):  # fmt: skip
        with pytest.raises(SystemExit) as info:
            estop.main(argv)
        assert info.value.code == 2, argv
