"""The simulated cell over REST: conveyor, objects with true poses, lights, boards, camera."""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any

import cv2
import numpy as np
import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from robot.model import ASEA
from tests.utils.factories import make_settings, make_tokens, migrate


@pytest.fixture(scope="module")
def sim_env(tmp_path_factory) -> Iterator[tuple[TestClient, dict[str, Any]]]:
    """One server with the simulated driver and camera for the whole module."""
    tmp = tmp_path_factory.mktemp("sim")
    settings = make_settings(tmp, driver="sim", camera="sim", sim_demo=False, time_scale=5.0)
    migrate(settings)
    tokens = make_tokens(settings)
    headers = {role: {"Authorization": f"Bearer {tok}"} for role, tok in tokens.items()}
    with TestClient(create_app(settings)) as c:
        yield c, headers


@pytest.fixture
def sim(sim_env) -> TestClient:
    return sim_env[0]


@pytest.fixture
def eng(sim_env) -> dict[str, str]:
    return sim_env[1]["engineer"]


@pytest.fixture
def roles(sim_env) -> dict[str, dict[str, str]]:
    return sim_env[1]


def test_not_simulated_cell_answers_409_with_a_clear_message(client, headers):
    for method, path in [
        ("get", "/api/sim/objects"),
        ("post", "/api/sim/conveyor"),
        ("get", "/api/sim/catalogue"),
        ("put", "/api/sim/lights/station"),
    ]:
        r = getattr(client, method)(
            path, headers=headers["engineer"], **({} if method == "get" else {"json": {}})
        )
        assert r.status_code == 409, path
        body = r.json()
        assert body["error"] == "not_simulated"
        assert "driver='ideal'" in body["detail"] and "VISIONCELL_DRIVER=sim" in body["detail"]


def test_engineer_role_is_required(sim, roles):
    r = sim.get("/api/sim/objects")
    assert r.status_code == 401 and r.json()["error"] == "unauthorized"
    for role in ("viewer", "operator"):
        r = sim.post("/api/sim/conveyor", json={"running": True}, headers=roles[role])
        assert r.status_code == 403
        assert r.json()["detail"] == f"this needs the engineer role; user 'test-{role}' is {role}"
        assert sim.get("/api/sim/objects", headers=roles[role]).status_code == 403


def test_catalogue_lists_wheels_parts_and_untrainable_parts(sim, eng):
    r = sim.get("/api/sim/catalogue", headers=eng)
    assert r.status_code == 200
    body = r.json()
    assert body["count"] == len(body["data"]) >= 14
    kinds = [e["kind"] for e in body["data"]]
    assert kinds.count("wheel") >= 5
    assert sum(not e["trainable"] for e in body["data"]) >= 2
    assert {"bracket-upright", "bracket-flat"} <= {e["name"] for e in body["data"]}


def test_spawn_list_read_and_delete_objects(sim, eng):
    r = sim.post(
        "/api/sim/objects",
        json={"name": "wheel-steel", "position_along_belt_m": 0.5, "yaw_rad": 0.25},
        headers=eng,
    )
    assert r.status_code == 201
    obj = r.json()["object"]
    T = np.array(obj["T_base_obj"])
    # The belt runs along +y at x = 0.8 from y = -1.3, surface at z = 0.45.
    np.testing.assert_allclose(T[:3, 3], [0.8, -0.8, 0.45], atol=1e-12)
    np.testing.assert_allclose(
        T[:2, :2], [[np.cos(0.25), -np.sin(0.25)], [np.sin(0.25), np.cos(0.25)]], atol=1e-12
    )
    assert obj["name"] == "wheel-steel" and obj["trainable"] is True
    listed = sim.get("/api/sim/objects", headers=eng).json()
    assert listed["count"] == len(listed["data"]) >= 1
    assert obj["id"] in [o["id"] for o in listed["data"]]
    assert sim.get(f"/api/sim/objects/{obj['id']}", headers=eng).json()["object"]["id"] == obj["id"]
    assert sim.delete(f"/api/sim/objects/{obj['id']}", headers=eng).status_code == 204
    r = sim.delete(f"/api/sim/objects/{obj['id']}", headers=eng)
    assert r.status_code == 404
    assert r.json() == {
        "error": "not_found",
        "detail": f"no object with id {obj['id']} on the belt",
    }
    assert sim.get(f"/api/sim/objects/{obj['id']}", headers=eng).status_code == 404


def test_spawn_rejects_unknown_names_and_positions(sim, eng):
    r = sim.post("/api/sim/objects", json={"name": "wheel-square"}, headers=eng)
    assert r.status_code == 422
    body = r.json()
    assert body["error"] == "validation_error"
    assert (
        "unknown catalogue name 'wheel-square'; valid names: wheel-5spoke, wheel-5spoke-redband"
        in body["detail"]
    )
    r = sim.post(
        "/api/sim/objects", json={"name": "wheel-steel", "position_along_belt_m": 9.0}, headers=eng
    )
    assert r.status_code == 422
    assert "position along the belt must be in [0, 2.6] m, got 9.0" in r.json()["detail"]


def test_spawn_beyond_the_free_slots_is_a_conflict(sim, eng):
    ids = []
    try:
        for _ in range(3):
            r = sim.post("/api/sim/objects", json={"name": "oil-filter"}, headers=eng)
            assert r.status_code == 201
            ids.append(r.json()["object"]["id"])
        r = sim.post("/api/sim/objects", json={"name": "oil-filter"}, headers=eng)
        assert r.status_code == 409
        assert r.json() == {
            "error": "sim_error",
            "detail": "all 3 slots for 'oil-filter' are in use; remove one first",
        }
    finally:
        for i in ids:
            sim.delete(f"/api/sim/objects/{i}", headers=eng)


def test_conveyor_settings_and_objects_riding_it(sim, eng):
    r = sim.post(
        "/api/sim/conveyor",
        json={"running": False, "speed_m_s": 0.1, "mode": "continuous"},
        headers=eng,
    )
    assert r.status_code == 200
    assert r.json()["conveyor"]["running"] is False and r.json()["conveyor"]["speed_m_s"] == 0.1
    obj = sim.post(
        "/api/sim/objects", json={"name": "gear-housing", "position_along_belt_m": 0.1}, headers=eng
    ).json()["object"]
    try:
        sim.post("/api/sim/conveyor", json={"running": True}, headers=eng)
        # 0.1 m/s at time_scale 5: about 0.25 m per wall second on an idle machine; a loaded
        # one runs the simulator slower than that, so wait for the travel, within a bound.
        deadline = time.monotonic() + 20.0
        while time.monotonic() < deadline:
            time.sleep(0.1)
            now = sim.get(f"/api/sim/objects/{obj['id']}", headers=eng).json()["object"]
            if now["position_along_belt_m"] - obj["position_along_belt_m"] > 0.05:
                break
        sim.post("/api/sim/conveyor", json={"running": False}, headers=eng)
        now = sim.get(f"/api/sim/objects/{obj['id']}", headers=eng).json()["object"]
        moved = now["position_along_belt_m"] - obj["position_along_belt_m"]
        assert 0.05 < moved < 1.0
        np.testing.assert_allclose(
            np.array(now["T_base_obj"])[1, 3] - np.array(obj["T_base_obj"])[1, 3], moved, atol=1e-9
        )
    finally:
        sim.delete(f"/api/sim/objects/{obj['id']}", headers=eng)
    r = sim.post("/api/sim/conveyor", json={"mode": "index", "dwell_s": 2.0}, headers=eng)
    assert r.json()["conveyor"]["mode"] == "index" and r.json()["conveyor"]["dwell_s"] == 2.0
    assert sim.post("/api/sim/conveyor/release", headers=eng).status_code == 200
    for bad, msg in [
        ({"mode": "sideways"}, "mode"),
        ({"speed_m_s": -1}, "speed_m_s"),
        ({"speed_m_s": 5}, "speed_m_s"),
    ]:
        r = sim.post("/api/sim/conveyor", json=bad, headers=eng)
        assert r.status_code == 422 and r.json()["detail"].startswith(msg)


def test_lights_can_be_dimmed(sim, eng):
    r = sim.get("/api/sim/lights", headers=eng)
    names = [light["name"] for light in r.json()["data"]]
    assert {"ceiling", "station", "fill", "ambient"} <= set(names)
    r = sim.put("/api/sim/lights/station", json={"intensity": 0.3}, headers=eng)
    assert r.status_code == 200 and r.json() == {"name": "station", "intensity": 0.3}
    r = sim.put("/api/sim/lights/laser", json={"intensity": 0.3}, headers=eng)
    assert r.status_code == 404 and "no light named 'laser'; lights: ceiling" in r.json()["detail"]
    r = sim.put("/api/sim/lights/station", json={"intensity": 9}, headers=eng)
    assert r.status_code == 422
    sim.put("/api/sim/lights/station", json={"intensity": 1.0}, headers=eng)


def test_boards_are_placed_and_removed(sim, eng):
    r = sim.put("/api/sim/boards/chessboard", json={"preset": "table"}, headers=eng)
    assert r.status_code == 200
    board = r.json()["board"]
    assert board["kind"] == "chessboard" and board["cols"] == 9 and board["square_m"] == 0.025
    assert np.array(board["T_base_board"])[2, 2] == -1.0  # face up
    T = np.eye(4)
    T[:3, 3] = (0.8, 0.0, 0.8)
    r = sim.put("/api/sim/boards/charuco", json={"T_base_board": T.tolist()}, headers=eng)
    assert r.status_code == 200 and r.json()["board"]["dictionary"] == "DICT_5X5_100"
    listed = sim.get("/api/sim/boards", headers=eng).json()
    assert listed["count"] == 2 and listed["kinds"] == ["chessboard", "charuco"]
    r = sim.put(
        "/api/sim/boards/charuco", json={"T_base_board": T.tolist(), "preset": "table"}, headers=eng
    )
    assert (
        r.status_code == 422 and r.json()["detail"] == "give exactly one of T_base_board and preset"
    )
    r = sim.put("/api/sim/boards/charuco", json={"T_base_board": [[1, 0], [0, 1]]}, headers=eng)
    assert r.status_code == 422 and "4x4" in r.json()["detail"]
    bad = np.eye(4)
    bad[0, 0] = 2.0
    r = sim.put("/api/sim/boards/charuco", json={"T_base_board": bad.tolist()}, headers=eng)
    assert r.status_code == 422 and "rigid transform" in r.json()["detail"]
    r = sim.put("/api/sim/boards/dartboard", json={"preset": "table"}, headers=eng)
    assert (
        r.status_code == 404
        and r.json()["detail"] == "no 'dartboard' board; boards: chessboard, charuco"
    )
    for kind in ("chessboard", "charuco"):
        assert sim.delete(f"/api/sim/boards/{kind}", headers=eng).status_code == 204
    assert sim.get("/api/sim/boards", headers=eng).json()["count"] == 0


def test_camera_serves_real_renders_and_sensor_settings_apply(sim, eng, roles):
    jpeg = None
    for _ in range(100):
        r = sim.get("/api/camera/frame.jpg", headers=roles["viewer"])
        if r.status_code == 200:
            jpeg = r.content
            break
        time.sleep(0.1)
    assert jpeg is not None
    img = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR)
    assert img.shape == (480, 640, 3)
    assert img.std() > 10.0  # a rendered scene, not a flat image
    r = sim.put("/api/sim/camera", json={"gain": 2.0, "noise_std_dn": 0.0}, headers=eng)
    assert r.status_code == 200 and r.json()["gain"] == 2.0 and r.json()["noise_std_dn"] == 0.0
    r = sim.put("/api/sim/camera", json={"gain": -1}, headers=eng)
    assert r.status_code == 422
    sim.put("/api/sim/camera", json={"gain": 1.0, "noise_std_dn": 1.5}, headers=eng)
    status = sim.get("/api/status", headers=roles["viewer"]).json()
    assert status["driver"]["name"] == "sim" and status["camera"]["name"] == "sim"


def test_sim_driver_moves_with_tracking_errors_in_the_job(sim, roles):
    ready = [float(v) for v in ASEA.q_ready]
    r = sim.post(
        "/api/robot/move?wait=true", json={"joints": ready, "speed": 1.0}, headers=roles["operator"]
    )
    assert r.status_code == 200
    result = r.json()["job"]["result"]
    assert result["completed"] is True
    assert result["final_error_rad"] <= 0.5e-3
    assert 0.0 < result["rms_tracking_error_rad"] <= 5e-3
    state = sim.get("/api/robot/state", headers=roles["viewer"]).json()["state"]
    assert state["q"] == pytest.approx(ready, abs=0.5e-3)


def test_conveyor_tells_where_the_station_is(sim, eng):
    """The console places objects at the station: GET /api/sim/conveyor gives its position,
    and the belt's length (a user lays out objects along it)."""
    conv = sim.get("/api/sim/conveyor", headers=eng).json()["conveyor"]
    spec = sim.app.state.runtime.sim.config.layout.conveyor
    assert conv["station_s_m"] == pytest.approx(spec.station_s_m)
    assert (
        conv["length_m"] == pytest.approx(spec.length_m) and conv["length_m"] > conv["station_s_m"]
    )
    obj = sim.post(
        "/api/sim/objects",
        json={"name": "gear-housing", "position_along_belt_m": conv["station_s_m"]},
        headers=eng,
    ).json()["object"]
    try:
        assert obj["position_along_belt_m"] == pytest.approx(spec.station_s_m)
    finally:
        sim.delete(f"/api/sim/objects/{obj['id']}", headers=eng)
