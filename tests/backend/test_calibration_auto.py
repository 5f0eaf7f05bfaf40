"""Automatic calibration through the API with the simulated cell (time-scaled driver)."""

from __future__ import annotations

import time

import numpy as np
import pytest
from fastapi.testclient import TestClient

from backend.api.deps import runtime_of
from backend.app import create_app
from tests.utils.factories import make_settings, make_tokens, migrate

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def sim_client(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("auto")
    s = make_settings(tmp, driver="sim", camera="sim", time_scale=8.0, camera_fps=20.0)
    migrate(s)
    tokens = make_tokens(s)
    app = create_app(s)
    with TestClient(app) as c:
        hdr = {role: {"Authorization": f"Bearer {t}"} for role, t in tokens.items()}
        yield c, hdr, app


def _wait(c, hdr, job_id, timeout_s=400.0):
    t0 = time.monotonic()
    seen = []
    while time.monotonic() - t0 < timeout_s:
        job = c.get(f"/api/jobs/{job_id}", headers=hdr["viewer"]).json()["job"]
        seen.append(job["progress"])
        if job["state"] != "running":
            return job, seen
        time.sleep(0.2)
    raise AssertionError(f"job {job_id} still running after {timeout_s} s")


def test_auto_calibration_end_to_end(sim_client):
    c, hdr, app = sim_client
    r = c.put("/api/sim/boards/chessboard", json={"preset": "table"}, headers=hdr["engineer"])
    assert r.status_code == 200, r.text
    T_true = np.asarray(r.json()["board"]["T_base_board"])
    # Give the planner a rough guess (3 cm and 4 deg off), as a person placing the board would.
    guess = T_true.copy()
    a = np.radians(4.0)
    guess[:3, :3] = guess[:3, :3] @ np.array(
        [[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]]
    )
    guess[:3, 3] += (0.03, -0.02, 0.0)
    r = c.post(
        "/api/calibration/auto",
        json={
            "board": "chessboard",
            "n_poses": 14,
            "activate": True,
            "seed": 1,
            "T_base_board": guess.tolist(),
            "speed": 1.0,
        },
        headers=hdr["engineer"],
    )
    assert r.status_code == 202, r.text
    job_id = r.json()["job"]["id"]
    # A second motion job is refused while the run holds the arm.
    busy = c.post("/api/calibration/auto", json={}, headers=hdr["engineer"])
    assert busy.status_code == 409 and busy.json()["error"] == "robot_busy", busy.text
    job, seen = _wait(c, hdr, job_id)
    assert job["state"] == "done", job
    assert seen == sorted(seen)
    res = job["result"]
    assert res["active"] and res["accepted"] >= 12 and res["coverage"] >= 0.7
    sess = c.get(f"/api/calibration/sessions/{res['session_id']}", headers=hdr["viewer"]).json()
    assert sess["session"]["source"] == "auto"
    assert sum(s["accepted"] for s in sess["samples"]) == res["accepted"]
    active = c.get("/api/calibration/active", headers=hdr["viewer"]).json()
    assert active["hand_eye"]["id"] == res["calibration_id"], active
    # Judged against the simulator's truth (never given to the run).
    truth = runtime_of(app).sim.truth.camera
    K = np.asarray(res["K"])
    assert abs(K[0, 0] / truth.K[0, 0] - 1) <= 0.002 and abs(K[1, 1] / truth.K[1, 1] - 1) <= 0.002
    T = np.asarray(res["T_ee_cam"])
    assert np.linalg.norm(T[:3, 3] - truth.T_ee_cam[:3, 3]) <= 1e-3


def test_cancel_stops_the_run_and_activates_nothing(sim_client):
    c, hdr, _ = sim_client
    before = c.get("/api/calibration/active", headers=hdr["viewer"]).json()
    r = c.put("/api/sim/boards/chessboard", json={"preset": "table"}, headers=hdr["engineer"])
    assert r.status_code == 200
    r = c.post("/api/calibration/auto", json={"seed": 2, "activate": True}, headers=hdr["engineer"])
    assert r.status_code == 202, r.text
    job_id = r.json()["job"]["id"]
    time.sleep(1.5)
    r = c.post(f"/api/jobs/{job_id}/cancel", headers=hdr["operator"])
    assert r.status_code == 200
    job, _ = _wait(c, hdr, job_id, timeout_s=30)
    assert job["state"] == "cancelled", job
    after = c.get("/api/calibration/active", headers=hdr["viewer"]).json()
    assert after == before
    # E-stop during a run: the run ends, nothing new is active, the arm must be reset.
    r = c.post("/api/calibration/auto", json={"seed": 3, "activate": True}, headers=hdr["engineer"])
    assert r.status_code == 202, r.text
    job_id = r.json()["job"]["id"]
    time.sleep(1.5)
    assert c.post("/api/robot/estop", headers=hdr["operator"]).status_code in (200, 202)
    job, _ = _wait(c, hdr, job_id, timeout_s=30)
    assert job["state"] in ("cancelled", "failed"), job
    assert c.get("/api/calibration/active", headers=hdr["viewer"]).json() == before
    r = c.post("/api/calibration/auto", json={}, headers=hdr["engineer"])
    assert r.status_code == 409 and "emergency stop" in r.json()["detail"]
    assert c.post("/api/robot/reset", headers=hdr["operator"]).status_code in (200, 202)


def test_bad_requests(sim_client):
    c, hdr, _ = sim_client
    far = np.eye(4)
    far[:3, :3] = np.diag([1.0, -1.0, -1.0])
    far[:3, 3] = (3.0, 0.0, 0.5)  # 3 m away: beyond the arm's reach
    r = c.post(
        "/api/calibration/auto", json={"T_base_board": far.tolist()}, headers=hdr["engineer"]
    )
    assert r.status_code == 422 and r.json()["error"] == "unreachable", r.text
    assert "cannot be calibrated from here" in r.json()["detail"]
    r = c.post("/api/calibration/auto", json={"n_poses": 2}, headers=hdr["engineer"])
    assert r.status_code == 422 and "error" in r.json() and "detail" in r.json()
    r = c.post(
        "/api/calibration/auto", json={"T_base_board": [[1, 0], [0, 1]]}, headers=hdr["engineer"]
    )
    assert r.status_code == 422 and "4x4" in r.text
    r = c.post("/api/calibration/auto", json={}, headers=hdr["operator"])
    assert r.status_code == 403
