"""The short version of benchmarks.segment_parts: two parts, one yaw."""

from __future__ import annotations

from benchmarks.segment_parts import main, run


def test_cut_off_parts_raise_the_flange_and_leave_the_wheel():
    res = run(1, parts=("pipe-flange", "wheel-steel"))
    by = {(s["part"], s["method"]): s for s in res["summary"]}
    flange_snake = by[("pipe-flange", "snake")]
    flange = by[("pipe-flange", "snake + cut-off parts")]
    assert flange["added"] == 1 and flange_snake["added"] == 0
    assert flange["iou_mean"] > flange_snake["iou_mean"] + 0.03
    assert flange["missed_mean"] < 0.5 * flange_snake["missed_mean"]
    wheel = by[("wheel-steel", "snake + cut-off parts")]
    assert wheel["added"] == 0
    assert wheel["iou_mean"] == by[("wheel-steel", "snake")]["iou_mean"] > 0.97


def test_bad_yaws_are_refused(capsys):
    import pytest

    with pytest.raises(SystemExit):
        main(["--yaws", "0"])
    assert "--yaws must be in 1..36, got 0" in capsys.readouterr().err
