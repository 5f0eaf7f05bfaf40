"""The inspection endpoints without a simulator: roles, bad input, 409s, empty lists, 404s."""

from __future__ import annotations

import pytest


def test_roles_and_bad_input(client, headers):
    assert client.post("/api/inspections", json={}).status_code == 401
    assert client.post("/api/inspections", json={}, headers=headers["viewer"]).status_code == 403
    assert client.post("/api/inspection/run", json={}, headers=headers["viewer"]).status_code == 403
    op = headers["operator"]
    for body in (
        {"policy": "guess"},
        {"sort": 1},
        {"max_views": 0},
        {"max_views": True},
        {"wait_s": -1},
        {"wait_s": 1e9},
        {"speed": 0},
        {"balance_light": "yes"},
        {"balance_light": 1},
        {"extra": 1},
    ):
        r = client.post("/api/inspections", json=body, headers=op)
        assert r.status_code == 422, (body, r.text)
        assert set(r.json()) == {"error", "detail"}
    for count in (0, -3, 10**6, True, 2.5):
        r = client.post("/api/inspection/run", json={"count": count}, headers=op)
        assert r.status_code == 422, (count, r.text)


def test_nothing_trained_and_no_run_are_conflicts(client, headers):
    op = headers["operator"]
    r = client.post("/api/inspections", json={}, headers=op)
    assert r.status_code == 409 and "teach" in r.json()["detail"], r.text
    assert r.json()["error"] == "nothing_trained"  # the console links its Models page on it
    r = client.post("/api/inspection/run", json={"count": 2}, headers=op)
    assert r.status_code == 409 and r.json()["error"] == "nothing_trained", r.text
    r = client.post("/api/inspection/stop", headers=op)
    assert r.status_code == 409 and "no inspection run" in r.json()["detail"]


def test_listing_filters_and_missing_rows(client, headers):
    v = headers["viewer"]
    assert client.get("/api/inspections", headers=v).json() == {"data": [], "count": 0}
    assert (
        client.get("/api/inspections?decision=recognized&policy=naive", headers=v).json()["count"]
        == 0
    )
    for q in ("decision=maybe", "policy=x", "limit=0", "limit=100000", "offset=-1"):
        assert client.get(f"/api/inspections?{q}", headers=v).status_code == 422, q
    r = client.get(
        "/api/inspections?since=2026-12-02T00:00:00&until=2026-12-01T00:00:00", headers=v
    )
    assert r.status_code == 422, r.text
    assert client.get("/api/inspections/5", headers=v).status_code == 404
    assert client.get("/api/inspections/5/images/0.jpg", headers=v).status_code == 404
    assert client.get("/api/inspections/0", headers=v).status_code == 422
    assert client.get(f"/api/inspections/{2**70}", headers=v).status_code == 422


@pytest.mark.parametrize("bad", ["0", "x"])
def test_image_index_is_bounded(client, headers, bad):
    r = client.get(f"/api/inspections/1/images/{bad}x.jpg", headers=headers["viewer"])
    assert r.status_code in (404, 422)
