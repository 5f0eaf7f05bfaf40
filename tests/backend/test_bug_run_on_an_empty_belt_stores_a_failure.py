"""Bug (the operator's path): after the teach wizard's "clear the station" the belt is stopped
and empty; *Start* showed "running" for five minutes with no word of waiting and no belt
state, then stored a ``failed`` row (``no_object``) that dropped the yield, its cycle time
the sum of a few stage times (2.37 s) although it had lasted 301 s.

Now a run waits for a part and says so (with the belt's state, which an operator reads and
starts through ``/api/belt``), stores no row while it waits, can be stopped while waiting,
and every stored row's ``duration_s`` is its wall time from start to end.  Driven through
REST with tokens printed by ``visioncell user add``."""

from __future__ import annotations

import time
from datetime import datetime

import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from tests.utils.cli import clear_station, cli_token, teach_at_station, wait_job
from tests.utils.factories import make_settings, migrate

pytestmark = pytest.mark.slow


def _job(client, h, job_id):
    return client.get(f"/api/jobs/{job_id}", headers=h).json()["job"]


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("emptybelt")
    settings = make_settings(tmp, driver="sim", camera="sim", sim_demo=False, time_scale=5.0)
    migrate(settings)
    heads = {
        role: {"Authorization": f"Bearer {cli_token(settings, f'user-{role}', role)}"}
        for role in ("viewer", "operator", "engineer")
    }
    with TestClient(create_app(settings)) as c:
        yield c, heads


def test_a_run_on_an_empty_belt_waits_without_a_row_and_times_the_inspection(cell):
    client, h = cell
    op, eng, viewer = h["operator"], h["engineer"], h["viewer"]
    teach_at_station(client, eng, "wheel-steel", part="wheel")
    before = client.get("/api/inspections", headers=viewer).json()["count"]

    # The belt as the Inspection page shows it: stopped and empty.
    belt = client.get("/api/belt", headers=viewer).json()
    assert belt["belt"]["running"] is False and belt["belt"]["objects"] == 0, belt
    assert "belt stopped" in belt["summary"], belt

    r = client.post("/api/inspection/run", json={"count": 1, "wait_s": 1}, headers=op)
    assert r.status_code == 202, r.text
    run_id = r.json()["job"]["id"]
    job = wait_job(client, op, run_id, until="waiting for a part", timeout_s=120)
    assert job["state"] == "running", job
    assert "belt stopped, 0 object(s) on it" in job["message"], job["message"]
    # Long past the run's wait_s: still waiting, and nothing stored.
    time.sleep(3.0)
    assert _job(client, op, run_id)["state"] == "running"
    assert client.get("/api/inspections", headers=viewer).json()["count"] == before

    # A part comes (placed at the station while the belt stands): inspected once.
    waited_from = time.monotonic()
    r = client.post("/api/sim/objects", json={"name": "wheel-steel", "yaw_rad": 0.4}, headers=eng)
    assert r.status_code == 201, r.text
    job = wait_job(client, op, run_id)
    assert job["state"] == "done" and job["result"]["inspected"] == 1, job
    page = client.get("/api/inspections", headers=viewer).json()
    assert page["count"] == before + 1
    row = page["data"][0]
    assert row["decision"] == "recognized", row["reason"]
    # the cycle time is the inspection's wall time (not the wait before it, not a sum of
    # some stages): from its start to its end
    wall = (datetime.fromisoformat(row["finished_at"])
            - datetime.fromisoformat(row["started_at"])).total_seconds()  # fmt: skip
    assert row["duration_s"] == pytest.approx(wall, abs=0.05), (row["duration_s"], wall)
    assert row["duration_s"] >= sum(row["durations"].values()) - 1e-3, row["durations"]
    assert row["duration_s"] <= time.monotonic() - waited_from + 0.05
    csv = client.get("/api/reports/export.csv", headers=viewer).text
    assert f"{row['duration_s']}" in csv

    # A run that waits can be stopped while it waits: no row either.
    clear_station(client, eng)
    r = client.post("/api/inspection/run", json={}, headers=op)
    assert r.status_code == 202, r.text
    run_id = r.json()["job"]["id"]
    wait_job(client, op, run_id, until="waiting for a part", timeout_s=120)
    assert client.post("/api/inspection/stop", headers=op).status_code == 202
    job = wait_job(client, op, run_id, timeout_s=60)
    assert job["state"] == "done" and job["result"]["inspected"] == 0, job
    assert job["result"]["stopped"] is True
    assert client.get("/api/inspections", headers=viewer).json()["count"] == before + 1

    # Inspect once with nothing there: the job fails no_object, and nothing is stored.
    r = client.post("/api/inspections", json={"wait_s": 1.0}, headers=op)
    assert r.status_code == 202, r.text
    job = wait_job(client, op, r.json()["job"]["id"], timeout_s=120)
    assert job["state"] == "failed" and job["error"]["error"] == "no_object", job
    assert client.get("/api/inspections", headers=viewer).json()["count"] == before + 1


def test_an_operator_starts_and_stops_the_belt(cell):
    client, h = cell
    op, viewer = h["operator"], h["viewer"]
    r = client.post("/api/belt", json={"running": True}, headers=viewer)
    assert r.status_code == 403, r.text
    for bad in ({"running": "yes"}, {"running": 1}, {}, {"running": True, "speed_m_s": 9}):
        r = client.post("/api/belt", json=bad, headers=op)
        assert r.status_code == 422, (bad, r.text)
        assert set(r.json()) == {"error", "detail"}
    r = client.post("/api/belt", json={"running": True}, headers=op)
    assert r.status_code == 200, r.text
    assert r.json()["belt"]["running"] is True and "belt running" in r.json()["summary"]
    r = client.post("/api/belt", json={"running": False}, headers=op)
    assert r.status_code == 200 and r.json()["belt"]["running"] is False, r.text
    # under the emergency stop the belt stays still
    assert client.post("/api/robot/estop", headers=op).status_code in (200, 202, 204)
    r = client.post("/api/belt", json={"running": True}, headers=op)
    assert r.status_code == 409, r.text
    assert client.get("/api/belt", headers=viewer).json()["belt"]["running"] is False
    assert client.post("/api/robot/reset", headers=h["engineer"]).status_code in (200, 202, 204)
