"""End to end in the simulated cell, through the API only: teach two models, run a short
continuous inspection in index mode, check the stored decisions and poses against the
simulator's truth; an e-stop during an inspection ends it ``failed`` with the reason."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from tests.utils.cli import wait_station_seen_empty
from tests.utils.factories import make_settings, make_tokens, migrate

pytestmark = pytest.mark.slow


def _wait(client, headers, job_id, *, until=None, timeout_s=300.0):
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout_s:
        job = client.get(f"/api/jobs/{job_id}", headers=headers).json()["job"]
        if job["state"] != "running" or (until is not None and until in job["message"]):
            return job
        time.sleep(0.2)
    raise AssertionError(f"job {job_id} still running after {timeout_s} s: {job['message']}")


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("inspect")
    settings = make_settings(tmp, driver="sim", camera="sim", sim_demo=False, time_scale=5.0)
    migrate(settings)
    tokens = make_tokens(settings)
    with TestClient(create_app(settings)) as c:
        yield c, {r: {"Authorization": f"Bearer {t}"} for r, t in tokens.items()}


def _teach(client, eng, engine, station):
    engine.clear_objects()
    engine.configure_conveyor(running=False, mode="index", dwell_s=None)
    gear = client.post("/api/models", json={"name": "gear-housing", "kind": "3d"}, headers=eng)
    wheel = client.post(
        "/api/models", json={"name": "wheel-steel", "kind": "2d", "part": "wheel"}, headers=eng
    )
    r = client.post(
        f"/api/models/{gear.json()['id']}/teach",
        json={"background": "grab", "wait_s": 60},
        headers=eng,
    )
    job = _wait(client, eng, r.json()["job"]["id"], until="waiting for an object")
    engine.spawn("gear-housing", s_m=station, yaw_rad=0.0)
    assert _wait(client, eng, job["id"])["state"] == "done"
    engine.clear_objects()
    engine.spawn("wheel-steel", s_m=station, yaw_rad=0.0)
    r = client.post(
        f"/api/models/{wheel.json()['id']}/teach", json={"background": "stored"}, headers=eng
    )
    assert _wait(client, eng, r.json()["job"]["id"])["state"] == "done"
    engine.clear_objects()


def test_teach_then_continuous_inspection_matches_truth(cell):
    client, h = cell
    eng, op = h["engineer"], h["operator"]
    engine = client.app.state.runtime.sim
    station = engine.config.layout.conveyor.station_s_m
    _teach(client, eng, engine, station)

    # Three objects, each stopped at the station in turn (index mode, the belt still): both
    # trained ones (turned, a few mm off) and an untrained one, during one continuous run.
    placed = [
        ("gear-housing", station + 0.002, 0.003, 0.15),
        ("oil-filter", station - 0.003, -0.002, 0.3),
        ("wheel-steel", station + 0.001, 0.002, -2.0),
    ]
    engine.clear_objects()
    engine.configure_conveyor(running=False, mode="index", dwell_s=None)
    r = client.post(
        "/api/inspection/run", json={"policy": "two-views", "count": 3, "wait_s": 60}, headers=op
    )
    assert r.status_code == 202, r.text
    run_id = r.json()["job"]["id"]
    # The arm is busy now: a second inspection is refused at once.
    busy = client.post("/api/inspections", json={}, headers=op)
    assert busy.status_code == 409, busy.text
    for k, (name, s, lat, yaw) in enumerate(placed):
        engine.spawn(name, s_m=s, lateral_m=lat, yaw_rad=yaw)
        t0 = time.monotonic()
        while client.get("/api/inspections", headers=op).json()["count"] < k + 1:
            assert time.monotonic() - t0 < 120, f"no inspection of {name}"
            time.sleep(0.3)
        engine.clear_objects()
        # the run sees the station empty before the next object comes
        wait_station_seen_empty(client, op, run_id, done=k + 1, count=len(placed))
    job = _wait(client, op, run_id)
    assert job["state"] == "done", job
    assert job["result"]["inspected"] == 3

    page = client.get("/api/inspections?limit=10", headers=h["viewer"]).json()
    assert page["count"] == 3
    rows = sorted(page["data"], key=lambda d: d["id"])
    seen = [
        ((r["truth"] or {}).get("name"), r["decision"], r["model"], r["reason"][:80]) for r in rows
    ]
    for row, (name, _s, _lat, _yaw) in zip(rows, placed, strict=True):
        assert row["truth"] is not None and row["truth"]["name"] == name, seen
        if name == "oil-filter":
            assert row["decision"] == "unknown", (row["reason"], row["scores"])
            continue
        assert row["decision"] == "recognized" and row["model"] == name, (
            name,
            row["decision"],
            row["reason"],
            row["scores"],
            row["truth"]["yaw_rad"],
        )
        assert row["viewpoints_visited"][0] == 1 and row["policy"] == "two-views"
        assert set(row["durations"]) >= {"move", "segment", "match", "decide"}
        assert row["pose"] is not None, row["reason"]
        # the fit held features at the heights the taught top views triangulated
        assert row["pose"]["triangulated"] > 0, row["pose"]
        T = np.array(row["pose"]["T_base_obj"])
        Tt = np.array(row["truth"]["T_base_obj"])
        assert np.linalg.norm(T[:2, 3] - Tt[:2, 3]) < 0.004, (name, T[:3, 3], Tt[:3, 3])
        if name == "gear-housing":  # no rotational symmetry
            dyaw = math.atan2(T[1, 0], T[0, 0]) - math.atan2(Tt[1, 0], Tt[0, 0])
            assert abs(math.remainder(dyaw, 2 * math.pi)) < math.radians(2.0)
        img = client.get(row["images"][0], headers=h["viewer"])
        assert img.status_code == 200 and img.content[:2] == b"\xff\xd8"
        one = client.get(f"/api/inspections/{row['id']}", headers=h["viewer"]).json()
        assert one["decision"] == row["decision"]
    only = client.get("/api/inspections?decision=unknown", headers=h["viewer"]).json()
    assert only["count"] == 1


def test_estop_during_inspection_ends_it_failed_with_reason(cell):
    client, h = cell
    op = h["operator"]
    engine = client.app.state.runtime.sim
    if client.get("/api/models", headers=op).json()["count"] == 0:  # run alone
        _teach(client, h["engineer"], engine, engine.config.layout.conveyor.station_s_m)
    engine.clear_objects()
    engine.configure_conveyor(running=False)
    before = client.get("/api/inspections", headers=op).json()["count"]
    # Waiting for a part is no inspection: an e-stop then cancels the job and stores nothing.
    r = client.post("/api/inspections", json={"wait_s": 60}, headers=op)
    assert r.status_code == 202, r.text
    job_id = r.json()["job"]["id"]
    _wait(client, op, job_id, until="waiting for a part", timeout_s=60)
    assert client.post("/api/robot/estop", headers=op).status_code in (200, 202, 204)
    job = _wait(client, op, job_id, timeout_s=30)
    assert job["state"] == "cancelled", job
    assert client.get("/api/inspections", headers=op).json()["count"] == before
    assert client.post("/api/robot/reset", headers=h["engineer"]).status_code in (200, 202, 204)
    # During an inspection: one complete failed row with the reason, nothing partial.
    engine.spawn("gear-housing", s_m=engine.config.layout.conveyor.station_s_m, yaw_rad=0.3)
    r = client.post("/api/inspections", json={"wait_s": 60}, headers=op)
    assert r.status_code == 202, r.text
    job_id = r.json()["job"]["id"]
    t0 = time.monotonic()
    while not any(w in client.get(f"/api/jobs/{job_id}", headers=op).json()["job"]["message"]
                  for w in ("inspecting the part", "viewpoint")):  # fmt: skip
        assert time.monotonic() - t0 < 120, "the inspection never began"
        time.sleep(0.05)
    assert client.post("/api/robot/estop", headers=op).status_code in (200, 202, 204)
    job = _wait(client, op, job_id, timeout_s=30)
    assert job["state"] == "cancelled", job
    page = client.get("/api/inspections?limit=500", headers=op).json()
    assert page["count"] == before + 1
    row = page["data"][0]
    assert row["decision"] == "failed" and "emergency stop" in row["reason"], row
    assert client.post("/api/robot/reset", headers=h["engineer"]).status_code in (200, 202, 204)
    engine.clear_objects()


def test_a_pose_on_too_little_is_looked_at_again_from_the_top(cell, monkeypatch):
    """The first top view's pose counted as resting on too little (the plane answer: one
    trained view, fewer than ``MIN_PARALLAX_POINTS`` correspondences): the inspection takes
    a second top view, turned about the camera's axis, and its pose is the one stored."""
    import dataclasses

    from backend.inspection import pose as pose_stage

    client, h = cell
    eng, op = h["engineer"], h["operator"]
    engine = client.app.state.runtime.sim
    if client.get("/api/models", headers=op).json()["count"] == 0:  # run alone
        _teach(client, eng, engine, engine.config.layout.conveyor.station_s_m)
    real, methods = pose_stage.estimate, []

    async def first_on_too_little(*a, **k):
        p = await real(*a, **k)
        methods.append(p.method)
        return dataclasses.replace(p, method="plane") if len(methods) == 1 else p

    monkeypatch.setattr(pose_stage, "estimate", first_on_too_little)
    engine.clear_objects()
    engine.configure_conveyor(running=False, mode="index", dwell_s=None)
    station = engine.config.layout.conveyor.station_s_m
    engine.spawn("gear-housing", s_m=station - 0.002, lateral_m=0.002, yaw_rad=0.7)
    r = client.post("/api/inspections", json={"policy": "two-views", "wait_s": 60}, headers=op)
    assert r.status_code == 202, r.text
    assert _wait(client, op, r.json()["job"]["id"])["state"] == "done"
    engine.clear_objects()
    row = client.get("/api/inspections?limit=1", headers=op).json()["data"][0]
    assert row["decision"] == "recognized" and row["model"] == "gear-housing", row["reason"]
    assert len(methods) == 2, methods  # the first top view's fit, then the second's
    visited = row["viewpoints_visited"]
    assert visited[0] == 1 and visited[-1] == 1 and visited.count(1) == 2, visited
    assert len(row["images"]) == len(visited)
    pose = row["pose"]
    assert pose is not None, row["reason"]
    assert pose["second_top_view"]["first"]["method"] == "plane"
    assert pose["second_top_view"]["chosen"] == "second", pose["second_top_view"]
    assert pose["method"] == "parallax"
    T, Tt = np.array(pose["T_base_obj"]), np.array(row["truth"]["T_base_obj"])
    assert np.linalg.norm(T[:2, 3] - Tt[:2, 3]) < 0.004, (T[:3, 3], Tt[:3, 3])
    dyaw = math.atan2(T[1, 0], T[0, 0]) - math.atan2(Tt[1, 0], Tt[0, 0])
    assert abs(math.remainder(dyaw, 2 * math.pi)) < math.radians(2.0)
    last = client.get(row["images"][-1], headers=h["viewer"])
    assert last.status_code == 200 and last.content[:2] == b"\xff\xd8"
