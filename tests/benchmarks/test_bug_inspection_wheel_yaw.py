"""Bug: ``benchmarks.inspection`` counted the wheels' yaw errors.

Its rule (yaw errors only for parts without rotational symmetry, not the wheels) tested a
catalogue entry's part against ``{"wheel"}``, but a wheel's part is its own name
(``wheel-steel``), so every wheel's yaw was scored: a steel wheel registered a quarter or
half turn off on its 8 holes and 4 bolts showed as a 180-degree yaw error.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchmarks.inspection import _record


def _row(yaw_est: float, yaw_true: float) -> dict:
    def T(yaw: float, x: float) -> list:
        M = np.eye(4)
        M[:2, :2] = [[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]]
        M[:3, 3] = (x, 0.0, 0.45)
        return M.tolist()

    return {
        "pose": {"at_exposure": T(yaw_est, 0.801), "T_base_obj": T(yaw_est, 0.801)},
        "truth": {"T_base_obj": T(yaw_true, 0.8)},
        "viewpoints_visited": [1, 2],
        "durations": {},
        "decision": "recognized",
        "reason": "",
    }


@pytest.mark.parametrize("name", ["wheel-steel", "wheel-5spoke", "wheel-10spoke-twin"])
def test_wheels_have_no_yaw_error(name):
    rec = _record("index", "two-views", name, {**_row(math.pi, 0.0), "model": name}, {})
    assert rec["yaw_err_deg"] is None
    assert rec["pos_err_mm"] == pytest.approx(1.0)


def test_parts_keep_their_yaw_error():
    row = {**_row(math.radians(0.5), 0.0), "model": "junction-box"}
    rec = _record("index", "two-views", "junction-box", row, {})
    assert rec["yaw_err_deg"] == pytest.approx(0.5)
