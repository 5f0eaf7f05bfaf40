"""Automatic calibration through the API with the simulated cell (time-scaled driver)."""

from __future__ import annotations

import time

import numpy as np
import pytest
from fastapi.testclient import TestClient

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
    if job["state"] != "done":
        sid = job["params"].get("session_id")
        print(job["error"])
        ss = c.get(f"/api/calibration/sessions/{sid}", headers=hdr["viewer"]).json()
        print([(s["name"], s["reason"]) for s in ss["samples"]])
    assert job["state"] == "done", job
    assert seen == sorted(seen)
    res = job["result"]
    assert res["active"] and res["accepted"] >= 12 and res["coverage"] >= 0.7
    sess = c.get(f"/api/calibration/sessions/{res['session_id']}", headers=hdr["viewer"]).json()
    assert sess["session"]["source"] == "auto"
    assert sum(s["accepted"] for s in sess["samples"]) == res["accepted"]
    active = c.get("/api/calibration/active", headers=hdr["viewer"]).json()
    print(active)
    truth = app.state.sim.truth.camera
    T = np.asarray(res["T_ee_cam"])
    dt = np.linalg.norm(T[:3, 3] - truth.T_ee_cam[:3, 3])
    print("hand-eye error mm", dt * 1e3, res)
    assert dt < 2e-3
