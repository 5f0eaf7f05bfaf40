"""The automatic threshold after two short teaches is never 0, and the product says what to
add.

The symptom: two models taught one round each gave ten impostor scores, all 0; the
conformal rule could not reach its 1 % false-accept target ("need 99") and took the
largest impostor score: a threshold of 0.000, under which an untrained part turned 45
degrees was named a model.  Now the automatic threshold keeps a floor
(:data:`~backend.recognition.thresholds.MIN_AUTO_THRESHOLD`, with the reason in the rule)
and the teach's result and the recognition settings carry plain advice (more rounds at
other yaws, more models) that the teach wizard shows.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import time

import numpy as np
import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from backend.recognition.thresholds import (
    MIN_AUTO_THRESHOLD,
    RECOMMENDED_ROUNDS,
    advice,
    floored,
    unsupported_floored,
)
from tests.utils.factories import TEST_SECRET, make_settings, migrate
from vision.recognition import ThresholdChoice


def _choice(t: float) -> ThresholdChoice:
    return ThresholdChoice(
        threshold=t, per_model={"a": t, "b": 0.3}, rule="conformal FAR <= 0.01 not reachable",
        rule_id="conformal-far", target_far=0.01, far_bound=None, far=0.0, frr=0.0,
        genuine=np.array([0.6, 0.7]), impostor=np.zeros(10), genuine_models=("a", "b"),
        confusion={}, candidate=t, per_viewpoint={1: t, 2: 0.02},
        per_model_viewpoint={1: {"a": t, "b": 0.0}}, candidate_viewpoint={1: t},
        own_viewpoint={2: {"a": 0.01, "b": 0.4}},
    )  # fmt: skip


def test_every_automatic_threshold_is_raised_to_the_floor():
    got, raised = floored(_choice(0.0))
    assert raised
    assert got.threshold == MIN_AUTO_THRESHOLD and got.candidate == MIN_AUTO_THRESHOLD
    assert got.per_model == {"a": MIN_AUTO_THRESHOLD, "b": 0.3}
    assert got.per_viewpoint == {1: MIN_AUTO_THRESHOLD, 2: MIN_AUTO_THRESHOLD}
    assert got.per_model_viewpoint == {1: {"a": MIN_AUTO_THRESHOLD, "b": MIN_AUTO_THRESHOLD}}
    assert got.own_viewpoint == {2: {"a": MIN_AUTO_THRESHOLD, "b": 0.4}}
    assert "raised from 0.000 to the floor 0.150" in got.rule
    same, raised = floored(_choice(0.4))  # above the floor: only the low ones move
    assert same.threshold == 0.4 and raised and same.per_viewpoint[2] == MIN_AUTO_THRESHOLD
    with pytest.raises(ValueError, match="floor"):
        floored(_choice(0.2), float("nan"))


def test_a_measured_threshold_stands_and_an_unsupported_one_is_floored():
    """The cell's floor stands in only where the scores could not bound the false accepts;
    a choice with a conformal bound (enough impostors) keeps its measured bars."""
    from dataclasses import replace

    bounded = replace(_choice(0.07), far_bound=0.009, rule="conformal FAR <= 0.01")
    same, raised = unsupported_floored(bounded)
    assert same is bounded and not raised
    got, raised = unsupported_floored(_choice(0.07))
    assert raised and got.threshold == MIN_AUTO_THRESHOLD


def test_the_advice_names_what_to_add():
    tips = advice({"a": 1, "b": 1}, impostors=10, reachable=False)  # kinds unknown: 3d's
    text = " ".join(tips)
    assert f"a (1 of {RECOMMENDED_ROUNDS['3d']})" in text and "b (1 of" in text
    assert "needs 99 views" in text and "give 10" in text
    assert "45 degrees" in text
    assert advice({"a": 8, "b": 8}) == ()
    assert "one more model" in " ".join(advice({"a": 8}))
    # Rounds by kind: a wheel (2d) taught once needs no more; a 3d part taught once does.
    need = {"wheel": RECOMMENDED_ROUNDS["2d"], "part": RECOMMENDED_ROUNDS["3d"]}
    text = " ".join(advice({"wheel": 1, "part": 1}, recommended=need))
    assert "part (1 of 8)" in text and "wheel (" not in text, text
    assert advice({"wheel": 1, "part": 8}, recommended=need) == ()


def _cli_token(settings, name: str, role: str) -> str:
    env = {**os.environ, "VISIONCELL_DATABASE_URL": settings.database_url,
           "VISIONCELL_SECRET_KEY": TEST_SECRET, "VISIONCELL_VAR_DIR": str(settings.var_dir)}  # fmt: skip
    r = subprocess.run([sys.executable, "-m", "backend.cli", "user", "add", name, "--role", role],
                       capture_output=True, text=True, env=env, timeout=120)  # fmt: skip
    assert r.returncode == 0, r.stderr
    return r.stdout.strip().splitlines()[-1]


def _wait(client, headers, job_id, *, until=None, timeout_s=900.0):
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout_s:
        job = client.get(f"/api/jobs/{job_id}", headers=headers).json()["job"]
        if job["state"] != "running" or (until is not None and until in job["message"]):
            return job
        time.sleep(0.3)
    raise AssertionError(f"job {job_id} still running after {timeout_s} s: {job['message']}")


@pytest.mark.slow
@pytest.mark.timeout(2400)
def test_two_one_round_teaches_leave_a_threshold_above_zero_and_advice(tmp_path):
    settings = make_settings(tmp_path, driver="sim", camera="sim", sim_demo=False, time_scale=5.0)
    migrate(settings)
    eng = {"Authorization": f"Bearer {_cli_token(settings, 'erin', 'engineer')}"}
    with TestClient(create_app(settings)) as client:
        engine = client.app.state.runtime.sim
        station = engine.config.layout.conveyor.station_s_m
        engine.clear_objects()
        engine.configure_conveyor(running=False, mode="index", dwell_s=None)
        results = []
        # A 3d part first (its teach grabs the backgrounds of every viewpoint), then a wheel.
        for k, (name, kind) in enumerate((("junction-box", "3d"), ("wheel-steel", "2d"))):
            r = client.post("/api/models", json={"name": name, "kind": kind}, headers=eng)
            assert r.status_code == 201, r.text
            mid = r.json()["id"]
            body = {"background": "grab" if k == 0 else "stored", "wait_s": 300, "yaw_rad": 0.0}
            if k == 1:
                engine.spawn(name, s_m=station, yaw_rad=0.0)
            r = client.post(f"/api/models/{mid}/teach", json=body, headers=eng)
            assert r.status_code == 202, r.text
            job = r.json()["job"]
            if k == 0:
                job = _wait(client, eng, job["id"], until="waiting for an object")
                engine.spawn(name, s_m=station, yaw_rad=0.0)
            job = _wait(client, eng, job["id"])
            assert job["state"] == "done", job
            results.append(job["result"])
            engine.clear_objects()
        # Each teach says where the model stands in the rounds its kind needs, and the next.
        assert results[0]["rounds"] == {"taught": 1, "recommended": 8, "next_round": 2,
                                        "next_yaw_deg": 45.0}  # fmt: skip
        assert results[1]["rounds"] == {"taught": 1, "recommended": 1, "next_round": None,
                                        "next_yaw_deg": None}  # fmt: skip
        listed = {
            m["name"]: m["rounds"] for m in client.get("/api/models", headers=eng).json()["data"]
        }
        assert listed == {"junction-box": {"taught": 1, "recommended": 8},
                          "wheel-steel": {"taught": 1, "recommended": 1}}  # fmt: skip
        thr = results[-1]["threshold"]
        assert thr["stored"] is True, thr
        assert thr["in_force"] >= MIN_AUTO_THRESHOLD and thr["threshold"] >= MIN_AUTO_THRESHOLD
        assert thr["in_force"] > 0.0
        text = " ".join(thr["advice"])
        assert "Teach more rounds" in text and "junction-box (1 of 8)" in text, thr
        assert "wheel-steel (" not in text, thr  # one round is all a 2d model needs
        # The settings in force say the same (the wizard's threshold card reads them).
        s = client.get("/api/recognition/settings", headers=eng).json()
        assert s["chosen_by"] == "auto" and s["global_threshold"] >= MIN_AUTO_THRESHOLD
        assert s["detail"]["advice"] == thr["advice"]
        assert s["detail"]["rounds"] == {"wheel-steel": 1, "junction-box": 1}
        assert all(v >= MIN_AUTO_THRESHOLD for v in s["detail"]["per_model"].values())
        # A 2d model's teach took one side view for the height alone: stored top views only.
        for res in results[1:]:
            assert {v["viewpoint"] for v in res["views"]} == {1}
            assert [s["viewpoint"] for s in res["shots"] if s["geometry_only"]] == [2]
            assert math.isfinite(res["geometry"]["measured"]["footprint_mm"][0])
