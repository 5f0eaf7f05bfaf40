"""Bug: a move at ``speed = 1e-6`` grew the server to 24 GB, ``1e-8`` answered a text/plain
500 and ``PUT /api/robot/speed {"speed": 1e-300}`` broke every later Home.

The edge refuses a speed below the stated floor with a JSON 422; the core refuses a plan
whose duration or sample count exceeds its bound (tests/robot/test_bug_trajectory_size_unbounded.py).
"""

from __future__ import annotations

import pytest

from robot.trajectory import MIN_SPEED

HOME_TO_READY = [0.0, 1.2, -1.4, -0.5, 0.0]


@pytest.mark.shared_app  # refused or computed only: nothing stored, nothing moved
@pytest.mark.parametrize("speed", [1e-6, 1e-8, 1e-300, 0.0, -0.5, 0.009])
def test_move_below_the_speed_floor_is_a_json_422(client, headers, speed):
    r = client.post(
        "/api/robot/move",
        json={"joints": HOME_TO_READY, "speed": speed},
        headers=headers["operator"],
    )
    assert r.status_code == 422, r.text
    assert r.headers["content-type"] == "application/json"
    assert r.json()["error"] == "validation_error"
    assert f"speed: Input should be greater than or equal to {MIN_SPEED}" in r.json()["detail"]
    assert client.get("/api/jobs", headers=headers["viewer"]).json()["count"] == 0


def test_tiny_default_speed_is_refused_and_home_still_works(client, headers):
    op = headers["operator"]
    r = client.put("/api/robot/speed", json={"speed": 1e-300}, headers=op)
    assert r.status_code == 422 and r.json()["error"] == "validation_error", r.text
    assert client.get("/api/robot/state", headers=op).json()["speed"] == 0.5
    r = client.post("/api/robot/home?wait=true", headers=op)
    assert r.status_code == 200 and r.json()["job"]["state"] == "done", r.text


@pytest.mark.shared_app  # refused or computed only: nothing stored, nothing moved
def test_boolean_speed_is_not_a_number(client, headers):
    r = client.put("/api/robot/speed", json={"speed": True}, headers=headers["operator"])
    assert r.status_code == 422 and "speed: Input should be a valid number" in r.json()["detail"]


def test_the_floor_itself_plans_a_bounded_move(client, headers):
    r = client.post(
        "/api/robot/move",
        json={"joints": HOME_TO_READY, "speed": MIN_SPEED},
        headers=headers["operator"],
    )
    assert r.status_code == 202, r.text
    job = r.json()["job"]
    assert job["params"]["speed"] == MIN_SPEED
    client.post(f"/api/jobs/{job['id']}/cancel", headers=headers["operator"])
