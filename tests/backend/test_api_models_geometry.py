"""A model's height and grasp point (migration 0008): entered through /api/models, stored,
served, used by the live index (the pick never reads the simulator's catalogue)."""

from __future__ import annotations

import math

import pytest

from backend.recognition import models as svc
from vision.errors import InvalidInput


def test_height_and_grasp_are_entered_kept_and_cleared(client, headers):
    eng = headers["engineer"]
    r = client.post("/api/models", json={"name": "bracket-upright", "kind": "3d",
                                         "height_m": 0.13, "grasp_obj": [0.01, 0.0, 0.012]},
                    headers=eng)  # fmt: skip
    assert r.status_code == 201, r.text
    m = r.json()
    assert m["height_m"] == 0.13 and m["grasp_obj"] == [0.01, 0.0, 0.012]
    assert m["geometry_source"] == "entered"
    live = client.app.state.runtime.live_index.model_of_name("bracket-upright")
    assert live.height_m == 0.13 and live.grasp_obj == (0.01, 0.0, 0.012)
    # Changing the height alone keeps the grasp point.
    r = client.patch(f"/api/models/{m['id']}", json={"height_m": 0.14}, headers=eng)
    assert r.status_code == 200, r.text
    assert r.json()["height_m"] == 0.14 and r.json()["grasp_obj"] == [0.01, 0.0, 0.012]
    # A grasp point above the object is refused, nothing changes.
    r = client.patch(f"/api/models/{m['id']}", json={"grasp_obj": [0.0, 0.0, 0.2]}, headers=eng)
    assert r.status_code == 422 and "height_m" in r.json()["detail"], r.text
    got = client.get(f"/api/models/{m['id']}", headers=headers["viewer"]).json()
    assert got["grasp_obj"] == [0.01, 0.0, 0.012]
    # Both cleared: nothing stored, nothing claimed.
    r = client.patch(f"/api/models/{m['id']}", json={"height_m": None, "grasp_obj": None},
                     headers=eng)  # fmt: skip
    assert r.status_code == 200, r.text
    assert r.json()["height_m"] is None and r.json()["geometry_source"] == ""
    # A model without them.
    plain = client.post("/api/models", json={"name": "gear", "kind": "2d"}, headers=eng).json()
    assert plain["height_m"] is None and plain["grasp_obj"] is None


@pytest.mark.parametrize(
    "body",
    [
        {"height_m": 0.0},
        {"height_m": 0.9},
        {"height_m": "0.1"},
        {"grasp_obj": [0.0, 0.0]},
        {"grasp_obj": [0.0, 0.0, 0.1, 0.0]},
        {"grasp_obj": [0.0, 0.9, 0.1]},
        {"grasp_obj": [0.0, 0.0, -0.01]},
        {"height_m": 0.05, "grasp_obj": [0.0, 0.0, 0.06]},
    ],
)
def test_bad_geometry_is_refused_without_a_row(client, headers, body):
    r = client.post("/api/models", json={"name": "x", "kind": "2d", **body},
                    headers=headers["engineer"])  # fmt: skip
    assert r.status_code == 422, r.text
    assert r.json()["error"] and r.json()["detail"]
    assert client.get("/api/models", headers=headers["viewer"]).json()["count"] == 0


def test_operators_may_not_enter_geometry(client, headers):
    r = client.post("/api/models", json={"name": "x", "kind": "2d", "height_m": 0.1},
                    headers=headers["operator"])  # fmt: skip
    assert r.status_code == 403


def test_service_checks_geometry():
    assert svc.check_geometry(0.1, (0.0, 0.01, 0.1)) == (0.1, (0.0, 0.01, 0.1))
    for h, g in ((math.nan, None), (None, (0.0, math.inf, 0.1)), (True, None), (None, "abc")):
        with pytest.raises(InvalidInput):
            svc.check_geometry(h, g)
