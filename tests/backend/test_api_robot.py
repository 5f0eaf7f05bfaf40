"""Robot endpoints: moves, limits, stop, e-stop, jobs, status."""

import math
import time

import pytest

from robot.model import ASEA

READY = [float(v) for v in ASEA.q_ready]


def _state(client, headers):
    return client.get("/api/robot/state", headers=headers["viewer"]).json()["state"]


def test_move_and_wait_reaches_the_target(client, headers):
    r = client.post(
        "/api/robot/move?wait=true",
        json={"joints": READY, "speed": 1.0},
        headers=headers["operator"],
    )
    assert r.status_code == 200
    job = r.json()["job"]
    assert job["state"] == "done" and job["result"]["completed"] is True
    assert _state(client, headers)["q"] == pytest.approx(READY, abs=1e-12)
    jobs = client.get("/api/jobs", headers=headers["viewer"]).json()
    assert jobs["count"] == 1 and jobs["data"][0]["id"] == job["id"]
    assert (
        client.get(f"/api/jobs/{job['id']}", headers=headers["viewer"]).json()["job"]["state"]
        == "done"
    )


def test_move_without_wait_answers_202_and_runs(client, headers):
    r = client.post("/api/robot/move", json={"joints": READY}, headers=headers["operator"])
    assert r.status_code == 202 and r.json()["job"]["state"] == "running"
    job_id = r.json()["job"]["id"]
    for _ in range(200):
        if (
            client.get(f"/api/jobs/{job_id}", headers=headers["viewer"]).json()["job"]["state"]
            != "running"
        ):
            break
        time.sleep(0.02)
    assert (
        client.get(f"/api/jobs/{job_id}", headers=headers["viewer"]).json()["job"]["state"]
        == "done"
    )


@pytest.mark.shared_app  # refused: nothing stored, nothing moved
@pytest.mark.parametrize(
    ("index", "value_deg", "detail"),
    [
        (
            1,
            20.0,
            "q2 = 0.349066 rad (20.00 deg) is outside its range [0.523599, 1.9635] rad ([30.00, 112.50] deg)",
        ),
        (
            2,
            -30.0,
            "q3 = -0.523599 rad (-30.00 deg) is outside its range [-2.19911, -1.09956] rad ([-126.00, -63.00] deg)",
        ),
        (
            4,
            170.0,
            "q5 = 2.96706 rad (170.00 deg) is outside its range [-2.89288, 2.89288] rad ([-165.75, 165.75] deg)",
        ),
    ],
)
def test_out_of_range_joint_is_422_naming_joint_and_limit(
    client, headers, index, value_deg, detail
):
    before = _state(client, headers)["q"]
    joints = list(ASEA.q_home)
    joints[index] = math.radians(value_deg)
    r = client.post("/api/robot/move", json={"joints": joints}, headers=headers["operator"])
    assert r.status_code == 422
    assert r.json() == {"error": "joint_limit", "detail": detail}
    assert _state(client, headers)["q"] == before
    assert client.get("/api/jobs", headers=headers["viewer"]).json()["count"] == 0


@pytest.mark.shared_app  # refused: nothing stored, nothing moved
@pytest.mark.parametrize(
    ("body", "fragment"),
    [
        ({"joints": [0, 1, -1.5]}, "joints: joints must have 5 values (q1..q5), got 3"),
        (
            {"joints": [0, 1.5, -1.5, 0, 0], "speed": 0},
            "speed: Input should be greater than or equal to 0.01",
        ),
        (
            {"joints": [0, 1.5, -1.5, 0, 0], "speed": 1.5},
            "speed: Input should be less than or equal to 1",
        ),
        ({"joints": ["a", 1.5, -1.5, 0, 0]}, "joints.0: Input should be a valid number"),
        ({}, "give exactly one of 'joints' and 'pose'"),
        (
            {"joints": [0, 1.5, -1.5, 0, 0], "pose": {"x": 0.8, "y": 0, "z": 1, "u": 0, "w": -1}},
            "give exactly one",
        ),
        ({"pose": {"x": 0.8, "y": 0, "z": 1, "u": 0}}, "pose.w: Field required"),
        (
            {"pose": {"x": 0.8, "y": 0, "z": 1, "u": 0, "w": -1}, "path": "curve"},
            "path: Input should be 'joint' or 'line'",
        ),
    ],
)
def test_malformed_move_is_422_with_reason(client, headers, body, fragment):
    r = client.post("/api/robot/move", json=body, headers=headers["operator"])
    assert r.status_code == 422
    assert r.json()["error"] == "validation_error" and fragment in r.json()["detail"]


def test_second_move_while_moving_is_409(client, headers):
    r = client.post(
        "/api/robot/move", json={"joints": READY, "speed": 0.05}, headers=headers["operator"]
    )
    assert r.status_code == 202
    r2 = client.post("/api/robot/home", headers=headers["operator"])
    assert r2.status_code == 409 and r2.json()["error"] == "robot_busy"
    assert "the arm is busy with job" in r2.json()["detail"]
    client.post("/api/robot/stop", headers=headers["operator"])


def test_stop_ends_a_move_early(client, headers):
    r = client.post(
        "/api/robot/move", json={"joints": READY, "speed": 0.05}, headers=headers["operator"]
    )
    job_id = r.json()["job"]["id"]
    time.sleep(0.1)
    client.post("/api/robot/stop", headers=headers["operator"])
    for _ in range(100):
        job = client.get(f"/api/jobs/{job_id}", headers=headers["viewer"]).json()["job"]
        if job["state"] != "running":
            break
        time.sleep(0.02)
    assert (
        job["state"] == "done"
        and job["result"] == pytest.approx(job["result"])
        and job["result"]["reason"] == "stopped"
    )
    assert _state(client, headers)["q"] != pytest.approx(READY, abs=1e-6)


def test_estop_refuses_motion_until_reset(client, headers):
    client.post("/api/robot/estop", headers=headers["operator"])
    r = client.post("/api/robot/move", json={"joints": READY}, headers=headers["operator"])
    assert r.status_code == 409
    assert r.json() == {
        "error": "robot_busy",
        "detail": "emergency stop is active: reset before moving",
    }
    client.post("/api/robot/reset", headers=headers["operator"])
    assert (
        client.post(
            "/api/robot/move?wait=true",
            json={"joints": READY, "speed": 1},
            headers=headers["operator"],
        ).status_code
        == 200
    )


def test_status_reports_driver_camera_database_and_versions(client, headers):
    for _ in range(100):
        s = client.get("/api/status", headers=headers["viewer"]).json()
        if s["camera"]["frames"] > 0:
            break
        time.sleep(0.05)
    assert s["driver"]["name"] == "ideal" and s["driver"]["connected"] is True
    assert s["camera"]["name"] == "folder" and s["camera"]["ok"] is True
    assert s["database"]["ok"] is True and s["database"]["revision"] == s["database"]["head"]
    assert set(s["versions"]) >= {"visioncell", "numpy", "opencv", "mujoco", "viser"}
    r = client.get("/api/camera/frame.jpg", headers=headers["viewer"])
    assert (
        r.status_code == 200
        and r.headers["content-type"] == "image/jpeg"
        and r.content[:2] == b"\xff\xd8"
    )


def test_unknown_job_and_route_are_404_with_error_body(client, headers):
    r = client.get("/api/jobs/nope", headers=headers["viewer"])
    assert r.status_code == 404 and r.json() == {
        "error": "not_found",
        "detail": "no job with id 'nope'",
    }
    r = client.get("/api/nothing-here", headers=headers["viewer"])
    assert r.status_code == 404 and r.json()["error"] == "not_found"


def test_speed_setting(client, headers):
    assert client.put(
        "/api/robot/speed", json={"speed": 0.8}, headers=headers["operator"]
    ).json() == {"speed": 0.8}
    assert client.get("/api/robot/state", headers=headers["viewer"]).json()["speed"] == 0.8
    r = client.put("/api/robot/speed", json={"speed": 2}, headers=headers["operator"])
    assert r.status_code == 422 and "speed" in r.json()["detail"]


def test_live_websocket_needs_a_token_then_streams_state(client, tokens):
    with client.websocket_connect("/api/ws") as ws:
        ws.send_json({"token": "vc_wrong"})
        msg = ws.receive()
        assert msg["type"] == "websocket.close" and msg["code"] == 4401
    with client.websocket_connect("/api/ws") as ws:
        ws.send_json({"token": tokens["viewer"]})
        hello = ws.receive_json()
        assert hello == {
            "type": "hello",
            "user": "test-viewer",
            "role": "viewer",
            "driver": "ideal",
        }
        state = ws.receive_json()
        assert state["type"] == "state" and len(state["state"]["q"]) == 5
