"""E-STOP with a valid token is never throttled, and never signs in through the database:
after five bad tokens from an address, its other requests get 429 but a valid token still
stops the cell; a token never seen valid still gets 401 (or 429 while blocked) and counts
as a failure, so the E-STOP is no way around the throttle."""

from __future__ import annotations

import pytest

from backend.api import deps
from backend.api.deps import runtime_of

BAD = {"Authorization": "Bearer vc_not-a-token-anyone-has"}


def test_a_blocked_address_still_stops_the_cell_with_a_valid_token(client, headers, settings):
    for _ in range(settings.signin_max_failures):
        assert client.get("/api/robot/state", headers=BAD).status_code == 401
    r = client.get("/api/robot/state", headers=headers["viewer"])
    assert r.status_code == 429, r.text  # the address is blocked for everything else
    r = client.post("/api/robot/estop", headers=headers["viewer"])
    assert r.status_code == 200, r.text
    assert r.json()["state"]["estopped"] is True
    # a token never seen valid gets the block's answer, not a way to test tokens
    r = client.post("/api/robot/estop", headers=BAD)
    assert r.status_code == 429 and r.json()["error"] == "too_many_attempts"
    assert "Retry-After" in r.headers


def test_an_unknown_token_gets_401_counted_by_the_throttle(client, headers, settings):
    r = client.post("/api/robot/estop")
    assert r.status_code == 401 and r.json()["error"] == "unauthorized"
    for _ in range(settings.signin_max_failures):
        r = client.post("/api/robot/estop", headers=BAD)
        assert r.status_code == 401 and set(r.json()) == {"error", "detail"}
    assert client.post("/api/robot/estop", headers=BAD).status_code == 429
    assert client.get("/api/robot/state", headers=headers["viewer"]).status_code == 429
    assert client.post("/api/robot/estop", headers=headers["viewer"]).status_code == 200
    assert runtime_of(client.app).cell.estopped


def test_estop_never_signs_in_through_the_database(client, headers, monkeypatch):
    rt = runtime_of(client.app)
    rt.auth_cache.clear()

    async def no_database(*a, **k):
        raise AssertionError("the E-STOP read the database to sign in")

    monkeypatch.setattr(deps, "authenticate_with_expiry", no_database)
    r = client.post("/api/robot/estop", headers=headers["viewer"])
    assert r.status_code == 200, r.text
    assert rt.cell.driver.state.estopped


def test_a_token_seen_valid_by_a_sign_in_is_known(client, tokens, settings):
    """A token created after the start (not read at start-up) is known once it signed in."""
    rt = runtime_of(client.app)
    eng = {"Authorization": f"Bearer {tokens['engineer']}"}
    r = client.post("/api/users", json={"name": "late-viewer", "role": "viewer"}, headers=eng)
    assert r.status_code == 201, r.text
    late = {"Authorization": f"Bearer {r.json()['token']}"}
    rt.auth_cache.clear()
    assert client.post("/api/robot/estop", headers=late).status_code == 401  # never seen valid
    assert client.get("/api/robot/state", headers=late).status_code == 200  # signs in
    rt.auth_cache.clear()
    assert client.post("/api/robot/estop", headers=late).status_code == 200


@pytest.mark.parametrize("how", ["disable", "revoke"])
def test_a_token_revoked_in_this_process_no_longer_stops_the_cell(client, tokens, headers, how):
    rt = runtime_of(client.app)
    eng = headers["engineer"]
    if how == "disable":
        r = client.delete("/api/users/test-viewer", headers=eng)
    else:
        listed = client.get("/api/users/test-viewer/tokens", headers=eng)
        assert listed.status_code == 200, listed.text
        (tok,) = listed.json()["data"]
        r = client.delete(f"/api/users/test-viewer/tokens/{tok['id']}", headers=eng)
    assert r.status_code == 200, r.text
    rt.auth_cache.clear()
    assert client.post("/api/robot/estop", headers=headers["viewer"]).status_code == 401
    assert not rt.cell.estopped
