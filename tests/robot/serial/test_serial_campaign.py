"""A short fault campaign, as ``python -m benchmarks.serial`` runs it: nothing lost, nothing twice.

The port vanishes far more often than in the benchmark (every ~30 command lines, for 50 ms),
so that faults hit the reconnection handshake itself within a run of a few seconds; the
campaign fails if the link goes dead (no fault injected for 20 s).
"""

from dataclasses import replace

import pytest

from benchmarks.serial import CAMPAIGN_FAULTS, bench_campaign

pytestmark = pytest.mark.slow


async def test_short_fault_campaign_loses_and_duplicates_nothing():
    config = replace(CAMPAIGN_FAULTS, vanish_p=0.03, vanish_s=0.05)
    result = await bench_campaign(150, lambda f, msg: None, config=config, stall_s=20.0)
    assert result["motion_commands"] > 10
    assert result["lost"] == 0
    assert result["duplicated"] == 0
    assert result["executed_but_reported_refused"] == 0
    assert result["outages"] >= 2 and result["faults"]["vanish"] >= 2
    assert result["reconnect"]["n"] >= 2
