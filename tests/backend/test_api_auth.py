"""Token auth and roles: viewer < operator < engineer."""

from tests.utils.factories import auth

HOME_BODY = {"joints": [0.0, 1.5707963, -1.5707963, 0.0, 0.0], "speed": 1.0}


def test_health_needs_no_token(client):
    r = client.get("/api/health")
    assert r.status_code == 200 and r.json()["status"] == "ok"


def test_missing_token_is_401_with_error_body(client):
    r = client.get("/api/robot/state")
    assert r.status_code == 401
    assert r.json() == {
        "error": "unauthorized",
        "detail": "missing bearer token (Authorization: Bearer TOKEN)",
    }
    assert r.headers["www-authenticate"] == "Bearer"


def test_wrong_token_is_401(client):
    r = client.get("/api/robot/state", headers=auth("vc_not-a-real-token"))
    assert r.status_code == 401
    assert r.json() == {"error": "unauthorized", "detail": "invalid, expired or revoked token"}


def test_viewer_reads_but_cannot_move(client, headers):
    assert client.get("/api/robot/state", headers=headers["viewer"]).status_code == 200
    before = client.get("/api/robot/state", headers=headers["viewer"]).json()["state"]["q"]
    r = client.post("/api/robot/move", json=HOME_BODY, headers=headers["viewer"])
    assert r.status_code == 403
    assert r.json() == {
        "error": "forbidden",
        "detail": "this needs the operator role; user 'test-viewer' is viewer",
    }
    assert client.get("/api/robot/state", headers=headers["viewer"]).json()["state"]["q"] == before
    assert client.get("/api/jobs", headers=headers["viewer"]).json() == {"data": [], "count": 0}


def test_operator_moves_but_cannot_configure(client, headers):
    r = client.post("/api/robot/home?wait=true", headers=headers["operator"])
    assert r.status_code == 200 and r.json()["job"]["state"] == "done"
    r = client.put(
        "/api/recognition/settings", json={"global_threshold": 0.7}, headers=headers["operator"]
    )
    assert r.status_code == 403
    assert r.json()["detail"] == "this needs the engineer role; user 'test-operator' is operator"
    assert (
        client.get("/api/recognition/settings", headers=headers["operator"]).json()["chosen_by"]
        == "default"
    )


def test_engineer_configures_and_manages_users(client, headers):
    r = client.put(
        "/api/recognition/settings",
        json={"global_threshold": 0.7, "note": "trial"},
        headers=headers["engineer"],
    )
    assert (
        r.status_code == 200
        and r.json()["global_threshold"] == 0.7
        and r.json()["chosen_by"] == "manual"
    )
    r = client.post(
        "/api/users", json={"name": "anna", "role": "viewer"}, headers=headers["engineer"]
    )
    assert r.status_code == 201
    token = r.json()["token"]
    assert client.get("/api/users/me", headers=auth(token)).json() == {
        "name": "anna",
        "role": "viewer",
    }
    users = client.get("/api/users", headers=headers["engineer"]).json()
    assert users["count"] == 4 and {u["name"] for u in users["data"]} >= {"anna", "test-engineer"}
    r = client.post(
        "/api/users", json={"name": "anna", "role": "viewer"}, headers=headers["engineer"]
    )
    assert r.status_code == 409 and r.json() == {
        "error": "conflict",
        "detail": "user 'anna' already exists",
    }
    r = client.post(
        "/api/users", json={"name": "bob", "role": "admin"}, headers=headers["engineer"]
    )
    assert (
        r.status_code == 422
        and "role: Input should be 'viewer', 'operator' or 'engineer' (got 'admin')"
        in r.json()["detail"]
    )
    assert client.delete("/api/users/anna", headers=headers["engineer"]).status_code == 200
    assert client.get("/api/users/me", headers=auth(token)).status_code == 401


def test_any_signed_in_user_may_press_estop(client, headers):
    r = client.post("/api/robot/estop", headers=headers["viewer"])
    assert r.status_code == 200 and r.json()["state"]["estopped"] is True
    assert client.post("/api/robot/reset", headers=headers["viewer"]).status_code == 403
    r = client.post("/api/robot/reset", headers=headers["operator"])
    assert r.status_code == 200 and r.json()["state"]["estopped"] is False
