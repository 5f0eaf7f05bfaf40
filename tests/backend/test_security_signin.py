"""Failed sign-ins are throttled per client address; tokens expire and can be revoked."""

from __future__ import annotations

import asyncio

import pytest
from fastapi.testclient import TestClient
from starlette.websockets import WebSocketDisconnect

from backend.app import create_app
from backend.auth import authenticate
from backend.db.session import Database
from backend.throttle import SignInThrottle, TooManyAttempts
from backend.view3d.access import ViewAccess
from tests.utils.factories import TEST_SECRET, make_settings, make_tokens, migrate


def auth(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


# -- the throttle itself ---------------------------------------------------------------------
class Clock:
    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


def test_throttle_blocks_after_max_failures_and_releases_after_block():
    clock = Clock()
    th = SignInThrottle(max_failures=3, window_s=60, block_s=30, clock=clock)
    for _ in range(2):
        th.check("10.0.0.1")
        th.failure("10.0.0.1")
    th.check("10.0.0.1")  # 2 failures: still allowed
    th.failure("10.0.0.1")
    with pytest.raises(TooManyAttempts) as info:
        th.check("10.0.0.1")
    assert info.value.retry_after_s == 30
    th.check("10.0.0.2")  # another address is not affected
    clock.t += 31
    th.check("10.0.0.1")


def test_throttle_window_slides():
    clock = Clock()
    th = SignInThrottle(max_failures=3, window_s=10, block_s=30, clock=clock)
    th.failure("a")
    th.failure("a")
    clock.t += 11  # the two old failures leave the window
    th.failure("a")
    th.check("a")


def test_throttle_memory_is_bounded():
    clock = Clock()
    th = SignInThrottle(max_failures=5, window_s=60, block_s=60, max_clients=100, clock=clock)
    for i in range(10_000):
        th.failure(f"10.{i // 65536}.{i // 256 % 256}.{i % 256}")
    assert len(th) <= 100


@pytest.mark.parametrize(
    "kwargs",
    [{"max_failures": 0}, {"max_failures": True}, {"window_s": 0}, {"block_s": float("nan")},
     {"max_clients": 0}],
)  # fmt: skip
def test_throttle_refuses_bad_options(kwargs):
    with pytest.raises(ValueError):
        SignInThrottle(**kwargs)


# -- REST and the WebSocket ----------------------------------------------------------------------
@pytest.fixture
def strict(tmp_path):
    s = make_settings(tmp_path, signin_max_failures=3, signin_window_s=60, signin_block_s=45)
    migrate(s)
    tokens = make_tokens(s)
    with TestClient(create_app(s)) as c:
        yield c, tokens, s


def test_rest_bad_tokens_then_429_even_for_a_good_token(strict):
    client, tokens, _ = strict
    good = auth(tokens["engineer"])
    assert client.get("/api/users/me", headers=good).status_code == 200
    for _ in range(3):
        r = client.get("/api/users/me", headers=auth("vc_wrong"))
        assert r.status_code == 401
    r = client.get("/api/users/me", headers=good)
    assert r.status_code == 429
    assert r.json()["error"] == "too_many_attempts" and "try again" in r.json()["detail"]
    assert 1 <= int(r.headers["retry-after"]) <= 45
    # The WebSocket of the same address is refused too, before the token is looked at.
    with client.websocket_connect("/api/ws") as ws:
        ws.send_json({"token": tokens["viewer"]})
        with pytest.raises(WebSocketDisconnect) as info:
            ws.receive_json()
    assert info.value.code == 4429


def test_websocket_bad_tokens_count_against_the_address(strict):
    client, tokens, _ = strict
    for _ in range(3):
        with client.websocket_connect("/api/ws") as ws:
            ws.send_json({"token": "vc_nope"})
            with pytest.raises(WebSocketDisconnect) as info:
                ws.receive_json()
        assert info.value.code == 4401
    r = client.get("/api/users/me", headers=auth(tokens["viewer"]))
    assert r.status_code == 429


def test_thresholds_are_settings(tmp_path):
    with pytest.raises(ValueError, match="signin_max_failures"):
        make_settings(tmp_path, signin_max_failures=0)
    with pytest.raises(ValueError, match="signin_block_s"):
        make_settings(tmp_path, signin_block_s=-1)


# -- expiry and revocation -----------------------------------------------------------------------
def test_token_api_issue_list_revoke(client, headers):
    eng = headers["engineer"]
    r = client.post("/api/users", json={"name": "eve", "role": "operator", "expires_in_days": 7},
                    headers=eng)  # fmt: skip
    assert r.status_code == 201, r.text
    first = r.json()["token"]
    r = client.post("/api/users/eve/tokens", json={"label": "tablet", "expires_in_days": 0.5},
                    headers=eng)  # fmt: skip
    assert r.status_code == 201, r.text
    second, info = r.json()["token"], r.json()["info"]
    assert info["label"] == "tablet" and info["expires_at"] and not info["revoked"]
    listed = client.get("/api/users/eve/tokens", headers=eng).json()
    assert listed["count"] == 2
    text = str(listed)
    assert first not in text and second not in text  # never the secret
    assert all(t["prefix"] for t in listed["data"])
    assert client.get("/api/users/me", headers=auth(second)).status_code == 200
    r = client.delete(f"/api/users/eve/tokens/{info['id']}", headers=eng)
    assert r.status_code == 200 and r.json()["revoked"] is True
    r = client.get("/api/users/me", headers=auth(second))
    assert r.status_code == 401 and "revoked" in r.json()["detail"]
    assert client.get("/api/users/me", headers=auth(first)).status_code == 200


@pytest.mark.shared_app  # refused or computed only: nothing stored, nothing moved
@pytest.mark.parametrize("days", [0, -1, 3651, "7", True, "1e999"])
def test_token_api_refuses_bad_expiry(client, headers, days):
    raw = '{"expires_in_days": 1e999}' if days == "1e999" else None
    kw = {"content": raw} if raw else {"json": {"expires_in_days": days}}
    r = client.post(
        "/api/users/viewer/tokens",
        **kw,
        headers={**headers["engineer"], "Content-Type": "application/json"},
    )
    assert r.status_code == 422, r.text


@pytest.mark.shared_app  # refused or computed only: nothing stored, nothing moved
def test_token_api_unknown_user_and_token(client, headers):
    eng = headers["engineer"]
    assert client.get("/api/users/nobody/tokens", headers=eng).status_code == 404
    assert client.delete("/api/users/viewer/tokens/999999", headers=eng).status_code == 404
    assert client.get("/api/users/viewer/tokens", headers=headers["operator"]).status_code == 403


def _expire(settings, token: str) -> None:
    from datetime import timedelta

    from sqlalchemy import update

    from backend.auth import hash_token
    from backend.db.models import ApiToken
    from backend.db.types import utcnow

    async def run() -> None:
        db = Database(settings.database_url)
        try:
            async with db.session() as session:
                await session.execute(
                    update(ApiToken)
                    .where(ApiToken.token_hash == hash_token(token, TEST_SECRET))
                    .values(expires_at=utcnow() - timedelta(seconds=1))
                )
        finally:
            await db.dispose()

    asyncio.run(run())


def test_expired_token_is_401_on_rest_and_4401_on_the_websocket(settings, tokens):
    with TestClient(create_app(settings)) as client:
        assert client.get("/api/users/me", headers=auth(tokens["viewer"])).status_code == 200
    _expire(settings, tokens["viewer"])
    with TestClient(create_app(settings)) as client:
        r = client.get("/api/users/me", headers=auth(tokens["viewer"]))
        assert r.status_code == 401 and "expired" in r.json()["detail"]
        with client.websocket_connect("/api/ws") as ws:
            ws.send_json({"token": tokens["viewer"]})
            with pytest.raises(WebSocketDisconnect) as info:
                ws.receive_json()
        assert info.value.code == 4401


def test_open_websocket_closes_4401_when_its_token_is_revoked(settings, tokens, monkeypatch):
    import backend.api.routes.live as live

    monkeypatch.setattr(live, "RECHECK_S", 0.2)
    with TestClient(create_app(settings)) as client:
        with client.websocket_connect("/api/ws") as ws:
            ws.send_json({"token": tokens["viewer"]})
            assert ws.receive_json()["type"] == "hello"
            _expire(settings, tokens["viewer"])
            with pytest.raises(WebSocketDisconnect) as info:
                for _ in range(1000):
                    ws.receive_json()
        assert info.value.code == 4401


def test_view3d_grant_ends_when_token_expires_and_panel_sign_in_is_throttled(settings, tokens):
    async def run() -> None:
        db = Database(settings.database_url)
        th = SignInThrottle(max_failures=2, window_s=60, block_s=60)
        access = ViewAccess(db, secret=TEST_SECRET, throttle=th)
        try:
            grant = await access.from_token(tokens["operator"], client="10.1.1.1")
            assert grant is not None
            async with db.session() as session:
                assert await authenticate(session, tokens["operator"], TEST_SECRET)
            await asyncio.to_thread(_expire, settings, tokens["operator"])
            assert await access.recheck(grant) is None  # controls removed
            assert await access.from_token(tokens["operator"], client="10.1.1.1") is None
            assert await access.from_token("vc_bad", client="10.1.1.1") is None
            with pytest.raises(TooManyAttempts):
                await access.from_token(tokens["engineer"], client="10.1.1.1")
            assert await access.from_token(tokens["engineer"], client="10.1.1.2") is not None
        finally:
            await db.dispose()

    asyncio.run(run())


def test_cli_user_add_with_expiry(tmp_path):
    from tests.backend.test_cli import _run

    r = _run(["user", "add", "tess", "--role", "viewer", "--expires-in", "30"], tmp_path)
    assert r.returncode == 0, r.stderr
    assert "valid until" in r.stdout
    assert r.stdout.strip().splitlines()[-1].startswith("vc_")
    bad = _run(["user", "add", "tom", "--expires-in", "0"], tmp_path)
    assert bad.returncode == 2 and "--expires-in" in bad.stderr and "0" in bad.stderr
