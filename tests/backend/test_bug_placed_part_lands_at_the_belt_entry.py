"""Bug (the operator's path): ``POST /api/sim/objects {"name": ...}`` put the part at the
belt's entry, 1.3 m from the station, whose position along the belt was found only in
``GET /api/sim/conveyor``.  Now ``"at": "station"`` (or ``"entry"``) says where, and a part
given no place goes to the station while the belt is stopped (to the entry while it runs).
Driven through REST with an engineer's token printed by ``visioncell user add``."""

from __future__ import annotations

import numpy as np
import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from tests.utils.cli import cli_token
from tests.utils.factories import make_settings, migrate


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("place")
    settings = make_settings(tmp, driver="sim", camera="sim", sim_demo=False, time_scale=5.0)
    migrate(settings)
    eng = {"Authorization": f"Bearer {cli_token(settings, 'erin', 'engineer')}"}
    with TestClient(create_app(settings)) as c:
        yield c, eng


def _y(obj):
    return float(np.array(obj["T_base_obj"])[1, 3])


def test_a_part_is_placed_at_the_station_by_name(sim):
    client, eng = sim
    conv = client.get("/api/sim/conveyor", headers=eng).json()["conveyor"]
    station_y = -1.3 + conv["station_s_m"]  # the belt's entry is at y = -1.3 m
    assert client.post("/api/sim/conveyor", json={"running": False}, headers=eng).status_code == 200
    r = client.post("/api/sim/objects", json={"name": "wheel-steel", "yaw_rad": 0.0}, headers=eng)
    assert r.status_code == 201, r.text
    assert _y(r.json()["object"]) == pytest.approx(station_y, abs=1e-9)  # stopped: the station
    r = client.post("/api/sim/objects", json={"name": "gear-housing", "at": "entry"}, headers=eng)
    assert r.status_code == 201 and _y(r.json()["object"]) == pytest.approx(-1.3, abs=1e-9)
    # running: the entry by default, the station when asked
    assert client.post("/api/sim/conveyor", json={"running": True, "speed_m_s": 0.0},
                       headers=eng).status_code == 200  # fmt: skip
    r = client.post("/api/sim/objects", json={"name": "oil-filter"}, headers=eng)
    assert r.status_code == 201 and _y(r.json()["object"]) == pytest.approx(-1.3, abs=1e-9)
    r = client.post("/api/sim/objects", json={"name": "oil-filter", "at": "station"}, headers=eng)
    assert r.status_code == 201
    assert _y(r.json()["object"]) == pytest.approx(station_y, abs=1e-9)
    client.post("/api/sim/conveyor", json={"running": False}, headers=eng)
    for o in client.get("/api/sim/objects", headers=eng).json()["data"]:
        client.delete(f"/api/sim/objects/{o['id']}", headers=eng)


@pytest.mark.parametrize(
    ("body", "says"),
    [
        ({"name": "wheel-steel", "at": "station", "position_along_belt_m": 0.5}, "not both"),
        ({"name": "wheel-steel", "at": "middle"}, "at"),
        ({"name": "wheel-steel", "at": 1}, "at"),
        ({"name": "wheel-steel", "at": None, "position_along_belt_m": 1e9}, "position"),
    ],
)
def test_bad_places_are_refused_with_the_reason(sim, body, says):
    client, eng = sim
    before = client.get("/api/sim/objects", headers=eng).json()["count"]
    r = client.post("/api/sim/objects", json=body, headers=eng)
    assert r.status_code == 422, r.text
    assert set(r.json()) == {"error", "detail"} and says in r.json()["detail"], r.json()
    assert client.get("/api/sim/objects", headers=eng).json()["count"] == before
