"""POST /api/inspection/belt-background: engineers only; a cell whose conveyor it cannot
jog (no simulator here) answers 409 with the reason, and no job starts."""

from __future__ import annotations


def test_belt_background_roles_and_refusal(client, headers):
    r = client.post("/api/inspection/belt-background", headers=headers["operator"])
    assert r.status_code == 403, r.text
    r = client.post("/api/inspection/belt-background", headers=headers["engineer"])
    assert r.status_code == 409, r.text
    assert r.json()["error"] == "conflict" and "conveyor" in r.json()["detail"]
    assert client.get("/api/jobs", headers=headers["engineer"]).json()["count"] == 0
