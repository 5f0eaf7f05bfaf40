"""Bug: ``POST /api/sim/objects {"name": "wheel-steel", "yaw_rad": Infinity}`` answered 422
but stored the object; from then on the object endpoints answered 422 and the camera task
and the 3D view loop died.  The API refuses non-finite and out-of-range values before it
calls the simulator, and the simulator validates before it changes its state."""

from __future__ import annotations

import math
import time

import pytest
from fastapi.testclient import TestClient

from backend.api.deps import runtime_of
from backend.app import create_app
from tests.utils.factories import make_settings, make_tokens, migrate


@pytest.fixture(scope="module")
def sim_env(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("sim-inf")
    settings = make_settings(tmp, driver="sim", camera="sim", sim_demo=False, time_scale=5.0)
    migrate(settings)
    eng = {"Authorization": f"Bearer {make_tokens(settings)['engineer']}"}
    with TestClient(create_app(settings)) as c:
        yield c, eng


# Raw JSON, as a client would send it: Python's json module reads Infinity and NaN.
BAD_BODIES = [
    '{"name": "wheel-steel", "yaw_rad": Infinity}',
    '{"name": "wheel-steel", "yaw_rad": NaN}',
    '{"name": "wheel-steel", "yaw_rad": 1e308}',
    '{"name": "wheel-steel", "yaw_rad": true}',
    '{"name": "wheel-steel", "lateral_m": -Infinity}',
    '{"name": "wheel-steel", "position_along_belt_m": 1e308}',
    '{"name": "wheel-steel", "position_along_belt_m": 50.0}',
]


@pytest.mark.parametrize("body", BAD_BODIES)
def test_bad_object_is_refused_and_nothing_is_stored(sim_env, body):
    c, eng = sim_env
    before = c.get("/api/sim/objects", headers=eng).json()["count"]
    r = c.post(
        "/api/sim/objects",
        content=body,
        headers={**eng, "Content-Type": "application/json"},
    )
    assert r.status_code == 422, r.text
    assert set(r.json()) == {"error", "detail"}
    r = c.get("/api/sim/objects", headers=eng)
    assert r.status_code == 200 and r.json()["count"] == before
    _camera_keeps_running(c, eng)


def _camera_keeps_running(c: TestClient, eng: dict[str, str]) -> None:
    """New frames keep arriving (the acquisition task did not die on a bad object)."""
    start = c.get("/api/camera/status", headers=eng).json()["frames"]
    deadline = time.monotonic() + 60.0
    while time.monotonic() < deadline:
        if c.get("/api/camera/status", headers=eng).json()["frames"] > start:
            r = c.get("/api/camera/frame.jpg", headers=eng)
            assert r.status_code == 200 and r.headers["content-type"] == "image/jpeg"
            return
        time.sleep(0.2)
    raise AssertionError("the camera stopped delivering frames")


def test_a_good_object_still_spawns_after_bad_ones(sim_env):
    c, eng = sim_env
    r = c.post("/api/sim/objects", json={"name": "wheel-steel", "yaw_rad": 0.5}, headers=eng)
    assert r.status_code == 201, r.text
    oid = r.json()["object"]["id"]
    assert c.get(f"/api/sim/objects/{oid}", headers=eng).status_code == 200
    assert c.delete(f"/api/sim/objects/{oid}", headers=eng).status_code == 204


def test_engine_validates_before_changing_state(sim_env):
    c, _ = sim_env
    sim = runtime_of(c.app).sim
    n = len(sim.objects())
    for kw in ({"yaw_rad": math.inf}, {"yaw_rad": math.nan}, {"yaw_rad": True}, {"s_m": 1e308}):
        with pytest.raises(ValueError):
            sim.spawn("wheel-steel", **kw)
    assert len(sim.objects()) == n
    with pytest.raises(ValueError, match="within 5 m"):
        sim.place_board(
            "chessboard", [[1, 0, 0, 1e308], [0, -1, 0, 0], [0, 0, -1, 0], [0, 0, 0, 1]]
        )
    with pytest.raises(ValueError, match="within 5 m"):
        sim.place_board("chessboard", [[1, 0, 0, 50.0], [0, -1, 0, 0], [0, 0, -1, 0], [0, 0, 0, 1]])
    with pytest.raises(ValueError):
        sim.configure_conveyor(speed_m_s=True)
    with pytest.raises(ValueError):
        sim.set_light("ambient", math.inf)


@pytest.mark.parametrize("x", [1e308, 50.0, True])
def test_board_far_away_is_refused(sim_env, x):
    c, eng = sim_env
    T = [[1, 0, 0, x], [0, -1, 0, 0], [0, 0, -1, 0], [0, 0, 0, 1]]
    r = c.put("/api/sim/boards/chessboard", json={"T_base_board": T}, headers=eng)
    assert r.status_code == 422 and set(r.json()) == {"error", "detail"}, r.text
    assert all(
        b["kind"] != "chessboard" for b in c.get("/api/sim/boards", headers=eng).json()["data"]
    )
