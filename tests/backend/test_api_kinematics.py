"""Kinematics endpoints and Cartesian moves (chapter eq. 20 through the API)."""

import math

import numpy as np
import pytest

from robot.kinematics import T_base_ee, fk
from robot.model import ASEA

READY_POSE = {"x": 0.8, "y": 0.0, "z": 1.0, "u": 0.0, "w": -1.0}


def _state(client, headers):
    return client.get("/api/robot/state", headers=headers["viewer"]).json()["state"]


@pytest.mark.shared_app  # refused or computed only: nothing stored, nothing moved
def test_fk_answers_pose_and_transform(client, headers):
    q = [0.3, 1.2, -1.5, 0.2, 0.4]
    r = client.post("/api/kinematics/fk", json={"joints": q}, headers=headers["viewer"])
    assert r.status_code == 200
    body = r.json()
    assert [body["pose"][k] for k in "xyzuw"] == pytest.approx(list(fk(q)), abs=1e-12)
    np.testing.assert_allclose(body["T_base_ee"], T_base_ee(q), atol=1e-12)


@pytest.mark.shared_app  # refused or computed only: nothing stored, nothing moved
def test_ik_lists_every_branch_with_its_limit_status(client, headers):
    r = client.post(
        "/api/kinematics/ik", json={"pose": READY_POSE, "roll": 0.0}, headers=headers["viewer"]
    )
    assert r.status_code == 200
    sols = r.json()["solutions"]
    assert len(sols) == 4
    assert len({s["branch"] for s in sols}) == 4
    ok = [s for s in sols if s["within_limits"]]
    assert len(ok) >= 1
    np.testing.assert_allclose(ok[0]["joints"], ASEA.q_ready, atol=1e-9)
    for s in sols:
        np.testing.assert_allclose(fk(s["joints"])[:3], [0.8, 0.0, 1.0], atol=1e-9)
        if not s["within_limits"]:
            assert s["violated_joints"] and s["detail"]


@pytest.mark.shared_app  # refused or computed only: nothing stored, nothing moved
def test_ik_of_an_unreachable_pose_is_422_with_the_reason(client, headers):
    far = {"x": 3.0, "y": 0.0, "z": 1.0, "u": 1.0, "w": 0.0}
    r = client.post("/api/kinematics/ik", json={"pose": far}, headers=headers["viewer"])
    assert r.status_code == 422 and r.json()["error"] == "unreachable"
    assert "out of reach" in r.json()["detail"]


@pytest.mark.shared_app  # refused or computed only: nothing stored, nothing moved
def test_ik_rejects_a_non_unit_approach(client, headers):
    bad = {"x": 0.8, "y": 0.0, "z": 1.0, "u": 0.5, "w": 0.5}
    r = client.post("/api/kinematics/ik", json={"pose": bad}, headers=headers["viewer"])
    assert r.status_code == 422 and "u" in r.json()["detail"] and "w" in r.json()["detail"]


@pytest.mark.shared_app  # refused or computed only: nothing stored, nothing moved
def test_kinematics_needs_a_token(client):
    assert (
        client.post("/api/kinematics/fk", json={"joints": [0, 1.5, -1.5, 0, 0]}).status_code == 401
    )


@pytest.mark.parametrize("path", ["joint", "line"])
def test_cartesian_move_reaches_the_pose(client, headers, path):
    body = {"pose": READY_POSE, "roll": 0.0, "speed": 1.0, "path": path}
    r = client.post("/api/robot/move?wait=true", json=body, headers=headers["operator"])
    assert r.status_code == 200, r.text
    job = r.json()["job"]
    assert job["state"] == "done" and job["kind"] == (
        "move_pose" if path == "joint" else "move_line"
    )
    np.testing.assert_allclose(
        fk(_state(client, headers)["q"]), [0.8, 0.0, 1.0, 0.0, -1.0], atol=1e-6
    )


@pytest.mark.shared_app  # refused or computed only: nothing stored, nothing moved
def test_unreachable_cartesian_move_is_422_and_nothing_moves(client, headers):
    before = _state(client, headers)["q"]
    far = {"x": 0.1, "y": 0.0, "z": 3.0, "u": 0.0, "w": 1.0}
    r = client.post("/api/robot/move", json={"pose": far}, headers=headers["operator"])
    assert r.status_code == 422 and r.json()["error"] == "unreachable"
    assert _state(client, headers)["q"] == before
    assert client.get("/api/jobs", headers=headers["viewer"]).json()["count"] == 0


@pytest.mark.shared_app  # refused or computed only: nothing stored, nothing moved
def test_pose_behind_the_joint_limits_names_the_joint(client, headers):
    # Straight above the column, tool pointing up: q2 would have to leave its range.
    up = {"x": 0.05, "y": 0.0, "z": 2.0, "u": math.cos(1.4), "w": math.sin(1.4)}
    r = client.post("/api/robot/move", json={"pose": up}, headers=headers["operator"])
    assert r.status_code == 422 and r.json()["error"] == "unreachable"
    assert "q" in r.json()["detail"]
