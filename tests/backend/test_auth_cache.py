"""The short-lived sign-in cache (``backend.authcache``): a revocation through this cell
applies to the very next request; one made by another process within the cache's TTL;
expired tokens and sign-ins read before a change are never served from it."""

from __future__ import annotations

import sqlite3
import time
from datetime import timedelta

from backend.authcache import TTL_S, AuthCache
from backend.db.models import User
from backend.db.types import utcnow


def _db_file(settings) -> str:
    return settings.database_url.split("///", 1)[1]


def test_revocation_here_applies_at_once(client, headers):
    hdr = headers["viewer"]
    assert client.get("/api/robot/state", headers=hdr).status_code == 200
    assert len(client.app.state.runtime.auth_cache) >= 1  # the sign-in is cached
    r = client.delete("/api/users/test-viewer", headers=headers["engineer"])
    assert r.status_code in (200, 204), r.text
    assert client.get("/api/robot/state", headers=hdr).status_code == 401


def test_revocation_elsewhere_applies_within_the_ttl(client, headers, settings):
    hdr = headers["operator"]
    assert client.get("/api/robot/state", headers=hdr).status_code == 200
    # Another process (plain sqlite3, not this process's sessions) revokes every token.
    with sqlite3.connect(_db_file(settings)) as conn:
        conn.execute("UPDATE api_tokens SET revoked = 1")
    t0 = time.monotonic()
    while client.get("/api/robot/state", headers=hdr).status_code == 200:
        assert time.monotonic() - t0 < TTL_S + 5.0, "still signed in long after the TTL"
        time.sleep(0.1)


def test_expired_and_stale_entries_are_not_served():
    cache = AuthCache(ttl_s=30.0)
    user = User(id=1, name="u", role="viewer", disabled=False, created_at=utcnow())
    cache.put("h1", user, utcnow() - timedelta(seconds=1), generation=cache.generation)
    assert cache.get("h1") is None  # the token expired
    before = cache.generation
    cache.clear()  # a user or token changed after the sign-in was read
    cache.put("h2", user, None, generation=before)
    assert cache.get("h2") is None
    cache.put("h3", user, None, generation=cache.generation)
    got = cache.get("h3")
    assert got is not None and got is not user and (got.id, got.role) == (1, "viewer")
    disabled = User(id=2, name="d", role="viewer", disabled=True, created_at=utcnow())
    cache.put("h4", disabled, None, generation=cache.generation)
    assert cache.get("h4") is None
