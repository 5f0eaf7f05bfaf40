"""A short run of the PLC benchmark (``benchmarks/plc.py``): REST, OPC UA and Modbus each
trigger a few inspections, press E-STOP and change recipes, and the JSON it prints last
accounts for every result (behaviour only: the timing is the benchmark's business)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

pytestmark = pytest.mark.slow

HANG_S = 600.0  # a bound on a hang only


def test_a_short_run_sees_every_result_once_over_each_protocol(data_dir):
    if not (data_dir / "recognition" / "coil20" / "obj2__30.png").is_file():
        pytest.skip("COIL-20 is absent from the data directory")
    args = ["--count", "3", "--estops", "2", "--sim-objects", "0", "--data-dir", str(data_dir)]
    r = subprocess.run([sys.executable, "-m", "benchmarks.plc", *args, "--json"],
                       capture_output=True, text=True, timeout=HANG_S)  # fmt: skip
    assert r.returncode == 0, r.stderr[-4000:]
    res = json.loads(r.stdout.strip().splitlines()[-1])
    assert res["benchmark"] == "plc" and res["count"] == 3
    assert {x["protocol"] for x in res["latency"]} == {"rest", "opcua", "modbus"}
    for proto in ("rest", "opcua", "modbus"):
        assert res["integrity"][proto] == {"triggers": 3, "results": 3, "unique": 3,
                                           "duplicates": 0}, proto  # fmt: skip
    assert res["integrity"]["all"] == {"stored": 9, "seen": 9, "lost": 0, "duplicated": 0}
    assert res["changeover"]["available"] is True, res["changeover"]
    for proto in ("opcua", "modbus"):
        assert len(res["changeover"]["select_to_result_s"][proto]) == 6, proto
    for proto in ("opcua", "modbus"):  # every press was seen by the PLC
        assert res["estop"][proto]["n"] == 2, (proto, res["estop"])
    assert res["opcua_ready_s"] > 0
