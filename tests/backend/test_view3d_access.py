"""3D view grants: signed links, tokens typed into the panel, revocation."""

from __future__ import annotations

import time

import pytest

from backend.auth import revoke_tokens
from backend.db.models import Role, User
from backend.db.session import Database
from backend.view3d.access import (
    LINK_PATH_PREFIX,
    ViewAccess,
    link_from_path,
    sign_view_link,
    verify_view_link,
)
from tests.utils.factories import TEST_SECRET

NOW = 1_800_000_000.0


def test_a_link_round_trips_and_carries_its_claims():
    link = sign_view_link(token_id=7, user_id=3, role=Role.operator, secret=TEST_SECRET, now=NOW)
    claims = verify_view_link(link, secret=TEST_SECRET, now=NOW + 10)
    assert claims is not None
    assert (claims.token_id, claims.user_id, claims.role) == (7, 3, Role.operator)
    assert claims.expires_at == pytest.approx(NOW + 120)


@pytest.mark.parametrize(
    "mutate",
    [
        lambda s: s.replace(".operator.", ".engineer."),  # a raised role
        lambda s: s.replace("v1.7.", "v1.8."),  # someone else's token
        lambda s: s[:-1] + ("A" if s[-1] != "A" else "B"),  # a forged signature
        lambda s: s + "x",
        lambda s: "",
        lambda s: "v1.7.3.operator." + "9" * 12 + "." + "A" * 43,
    ],
)
def test_a_tampered_link_is_refused(mutate):
    link = sign_view_link(token_id=7, user_id=3, role=Role.operator, secret=TEST_SECRET, now=NOW)
    assert verify_view_link(mutate(link), secret=TEST_SECRET, now=NOW) is None


def test_a_link_expires_and_needs_the_same_secret():
    link = sign_view_link(
        token_id=7, user_id=3, role=Role.viewer, secret=TEST_SECRET, ttl_s=5, now=NOW
    )
    assert verify_view_link(link, secret=TEST_SECRET, now=NOW + 4) is not None
    assert verify_view_link(link, secret=TEST_SECRET, now=NOW + 6) is None
    assert verify_view_link(link, secret="another-secret-of-16+", now=NOW) is None


@pytest.mark.parametrize(
    "kwargs",
    [
        {"token_id": True},
        {"token_id": 0},
        {"user_id": 2**63},
        {"user_id": 1.0},
        {"ttl_s": 0},
        {"ttl_s": 1e9},
        {"ttl_s": float("nan")},
        {"role": "engineer"},
    ],
)
def test_signing_refuses_bad_values(kwargs):
    args = {"token_id": 1, "user_id": 1, "role": Role.viewer, "ttl_s": 60.0, **kwargs}
    with pytest.raises(ValueError, match=next(iter(kwargs))):
        sign_view_link(secret=TEST_SECRET, **args)


def test_the_link_rides_the_websocket_path():
    assert link_from_path(LINK_PATH_PREFIX + "abc") == "abc"
    assert link_from_path(LINK_PATH_PREFIX + "abc?x=1") == "abc"
    assert link_from_path("/") is None
    assert link_from_path(None) is None
    assert link_from_path(LINK_PATH_PREFIX) is None


async def test_tokens_links_and_revocation_against_the_database(settings, tokens):
    db = Database(settings.database_url)
    access = ViewAccess(db, secret=TEST_SECRET)
    try:
        assert access.open_grant() is None
        assert await access.from_token("vc_not-a-token") is None
        assert await access.from_token("") is None
        op = await access.from_token(tokens["operator"])
        assert op is not None and op.role is Role.operator and op.via == "token"
        assert op.allows(Role.viewer) and op.allows(Role.operator)
        assert not op.allows(Role.engineer)

        link = await access.link_for_token(tokens["operator"])
        assert link is not None
        by_link = await access.from_link(link)
        assert by_link is not None and by_link.role is Role.operator and by_link.via == "link"
        assert by_link.token_id == op.token_id
        assert await access.from_link(link, now=time.time() + 3600) is None  # expired
        assert await access.link_for_token("vc_nope") is None

        # A link signed for another user's token id is refused, even with a valid signature.
        eng = await access.from_token(tokens["engineer"])
        assert eng is not None
        forged = sign_view_link(
            token_id=eng.token_id, user_id=99, role=Role.engineer, secret=TEST_SECRET
        )
        assert await access.from_link(forged) is None

        assert await access.recheck(op) == op
        async with db.session() as s:
            user = await s.get(User, 2)  # test-operator (users are made in Role order)
            assert user is not None and user.name == "test-operator"
            assert await revoke_tokens(s, user) == 1
        assert await access.recheck(op) is None
        assert await access.recheck(by_link) is None
        assert await access.from_link(link) is None
        assert await access.from_token(tokens["operator"]) is None

        # A lowered role is applied on the next check.
        async with db.session() as s:
            user = await s.get(User, 3)
            assert user is not None and user.name == "test-engineer"
            user.role = Role.viewer.name
        fresh = await access.recheck(eng)
        assert fresh is not None and fresh.role is Role.viewer
    finally:
        await db.dispose()


def test_without_auth_every_client_is_an_engineer(settings):
    access = ViewAccess(Database(settings.database_url), secret=TEST_SECRET, auth_enabled=False)
    grant = access.open_grant()
    assert grant is not None and grant.role is Role.engineer and grant.token_id is None


def test_the_console_gets_a_link_for_its_own_token(tmp_path):
    from fastapi.testclient import TestClient

    from backend.app import create_app
    from tests.utils.factories import make_settings, make_tokens, migrate

    settings = make_settings(tmp_path, view3d_enabled=True)
    migrate(settings)
    toks = make_tokens(settings)
    with TestClient(create_app(settings)) as c:
        assert c.post("/api/view3d/link").status_code == 401
        bad = c.post("/api/view3d/link", headers={"Authorization": "Bearer vc_nope"})
        assert bad.status_code == 401 and bad.json()["error"] == "unauthorized"
        r = c.post("/api/view3d/link", headers={"Authorization": f"Bearer {toks['viewer']}"})
        assert r.status_code == 200, r.text
        body = r.json()
        assert body["ws_path"] == LINK_PATH_PREFIX + body["link"]
        assert body["viser_port"] == settings.viser_port and body["user"] == "test-viewer"
        claims = verify_view_link(body["link"], secret=TEST_SECRET)
        assert claims is not None and claims.role is Role.viewer
