"""The short-lived sign-in cache (``backend.authcache``): a revocation through this cell
applies to the very next request; one made by another process within the cache's TTL;
expired tokens and sign-ins read before a change are never served from it."""

from __future__ import annotations

import asyncio
import logging
import sqlite3
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from datetime import timedelta

from backend.authcache import REFRESH_AHEAD_FRACTION, TTL_S, AuthCache, SignIn
from backend.db.models import User
from backend.db.types import utcnow
from tests.utils.clock import SteppedClock


def _db_file(settings) -> str:
    return settings.database_url.split("///", 1)[1]


def test_revocation_here_applies_at_once(client, headers):
    hdr = headers["viewer"]
    assert client.get("/api/robot/state", headers=hdr).status_code == 200
    assert len(client.app.state.runtime.auth_cache) >= 1  # the sign-in is cached
    r = client.delete("/api/users/test-viewer", headers=headers["engineer"])
    assert r.status_code in (200, 204), r.text
    assert client.get("/api/robot/state", headers=hdr).status_code == 401


def test_revocation_elsewhere_applies_within_the_ttl(client, headers, settings, monkeypatch):
    # The cache's clock moves only when the test moves it (a stalled test process cannot
    # age an entry), and this cache does not refresh ahead.
    import backend.authcache

    clock = SteppedClock()
    monkeypatch.setattr(backend.authcache, "time", clock)
    client.app.state.runtime.auth_cache.refresh_ahead = False
    hdr = headers["operator"]
    assert client.get("/api/robot/state", headers=hdr).status_code == 200
    # Another process (plain sqlite3, not this process's sessions) revokes every token.
    with sqlite3.connect(_db_file(settings)) as conn:
        conn.execute("UPDATE api_tokens SET revoked = 1")
    clock.advance(TTL_S)
    assert client.get("/api/robot/state", headers=hdr).status_code == 401


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


# -- one lookup per token in flight, refreshed ahead -------------------------------------------
def _user(uid: int = 1, role: str = "viewer") -> User:
    return User(id=uid, name=f"u{uid}", role=role, disabled=False, created_at=utcnow())


class _Lookups:
    """A database sign-in that counts its calls, takes ``delay_s`` and answers ``found``
    (a user and expiry, None: refused) or raises ``error``."""

    def __init__(self, found: SignIn | None, *, delay_s: float = 0.05) -> None:
        self.calls = 0
        self.found = found
        self.delay_s = delay_s
        self.error: Exception | None = None

    async def __call__(self) -> SignIn | None:
        self.calls += 1
        await asyncio.sleep(self.delay_s)
        if self.error is not None:
            raise self.error
        return self.found


def test_concurrent_sign_ins_of_one_token_share_one_lookup():
    cache, lookup = AuthCache(ttl_s=30.0), _Lookups((_user(), None))

    async def run() -> list[User | None]:
        return await asyncio.gather(*(cache.sign_in("h", lookup) for _ in range(10)))

    got = asyncio.run(run())
    assert lookup.calls == 1 and cache.lookups == 1 and cache.shared == 9
    assert all(u is not None and (u.id, u.role) == (1, "viewer") for u in got)
    assert len({id(u) for u in got}) == 10  # each request its own copy


def test_a_refused_lookup_is_shared_but_never_cached():
    cache, lookup = AuthCache(ttl_s=30.0), _Lookups(None)

    async def run() -> list[User | None]:
        return await asyncio.gather(*(cache.sign_in("h", lookup) for _ in range(5)))

    assert asyncio.run(run()) == [None] * 5 and lookup.calls == 1 and len(cache) == 0
    asyncio.run(cache.sign_in("h", lookup))
    assert lookup.calls == 2  # the next request asks the database again


def test_a_lookup_that_started_before_a_change_is_not_shared_after_it():
    cache, lookup = AuthCache(ttl_s=30.0), _Lookups((_user(), None), delay_s=0.1)

    async def run() -> None:
        first = asyncio.create_task(cache.sign_in("h", lookup))
        await asyncio.sleep(0.02)
        cache.clear()  # a user or token change committed while the lookup is in flight
        second = await cache.sign_in("h", lookup)  # looks up itself
        assert (await first) is not None and second is not None

    asyncio.run(run())
    assert lookup.calls == 2 and cache.shared == 0


def test_the_setting_off_looks_each_request_up_itself():
    cache, lookup = AuthCache(ttl_s=30.0, refresh_ahead=False), _Lookups((_user(), None))

    async def run() -> None:
        await asyncio.gather(*(cache.sign_in("h", lookup) for _ in range(4)))

    asyncio.run(run())
    assert lookup.calls == 4 and cache.shared == 0


def test_an_entry_used_late_in_its_ttl_is_refreshed_in_the_background():
    clock = SteppedClock()
    cache, lookup = AuthCache(ttl_s=0.5, clock=clock), _Lookups((_user(), None), delay_s=0.1)

    async def run() -> None:
        await cache.sign_in("h", lookup)
        first = cache._entries["h"]
        clock.advance(0.5 * (1 - REFRESH_AHEAD_FRACTION) + 0.02)
        for _ in range(5):  # answered from the entry at once, one lookup started
            user = await asyncio.wait_for(cache.sign_in("h", lookup), 0.05)
            assert user is not None
        assert cache.refreshing == 1 and lookup.calls == 2
        while cache.refreshing:
            await asyncio.sleep(0.01)
        assert cache._entries["h"].until > first.until  # replaced before it expired
        # No request waited: every one but the first was answered from an entry.
        assert cache.lookups == 2 and cache.refreshes == 1

    asyncio.run(run())


def test_a_refresh_that_finds_the_token_refused_drops_the_entry():
    clock = SteppedClock()
    cache, lookup = AuthCache(ttl_s=0.5, clock=clock), _Lookups((_user(), None))

    async def run() -> None:
        await cache.sign_in("h", lookup)
        clock.advance(0.5 * (1 - REFRESH_AHEAD_FRACTION) + 0.02)
        lookup.found = None  # revoked in the database
        assert await cache.sign_in("h", lookup) is not None  # the entry, still valid
        while cache.refreshing:
            await asyncio.sleep(0.01)
        assert len(cache) == 0 and await cache.sign_in("h", lookup) is None

    asyncio.run(run())


def test_a_failed_background_lookup_is_logged_once_and_the_entry_expires(caplog):
    clock = SteppedClock()
    cache, lookup = AuthCache(ttl_s=0.4, clock=clock), _Lookups((_user(), None), delay_s=0.0)

    async def run() -> None:
        await cache.sign_in("h", lookup)
        started = clock()
        clock.advance(0.4 * (1 - REFRESH_AHEAD_FRACTION) + 0.02)
        lookup.error = RuntimeError("database down")
        for _ in range(5):
            assert cache.get("h", refresh=lookup) is not None
            await asyncio.sleep(0.01)
        assert lookup.calls == 2  # not tried again for the same entry
        while cache.refreshing:
            await asyncio.sleep(0.01)
        clock.now = started + 0.4
        assert cache.get("h") is None  # expired at its until, not extended

    with caplog.at_level(logging.WARNING, logger="backend.authcache"):
        asyncio.run(run())
    assert len(caplog.records) == 1 and "database down" in caplog.records[0].getMessage()
    assert cache.refresh_failures == 1


def test_close_cancels_background_lookups():
    clock = SteppedClock()
    cache, lookup = AuthCache(ttl_s=0.4, clock=clock), _Lookups((_user(), None), delay_s=0.0)

    async def run() -> None:
        await cache.sign_in("h", lookup)
        clock.advance(0.4 * (1 - REFRESH_AHEAD_FRACTION) + 0.02)
        lookup.delay_s = 60.0
        cache.get("h", refresh=lookup)
        (task,) = cache._background.tasks
        await asyncio.sleep(0.01)
        await cache.close()
        assert task.cancelled() and cache.refreshing == 0 and len(cache) == 0

    asyncio.run(run())


def test_requests_with_one_token_share_one_database_sign_in(client, headers, monkeypatch):
    import backend.api.deps as deps

    calls = 0
    real = deps.authenticate_with_expiry

    async def slow(session, token, secret):
        nonlocal calls
        calls += 1
        await asyncio.sleep(0.3)  # every request below arrives while it is in flight
        return await real(session, token, secret)

    monkeypatch.setattr(deps, "authenticate_with_expiry", slow)
    client.app.state.runtime.auth_cache.clear()
    n = 8
    barrier = threading.Barrier(n)

    def get(_: int) -> int:
        barrier.wait()
        return client.get("/api/robot/state", headers=headers["operator"]).status_code

    with ThreadPoolExecutor(n) as pool:
        codes = list(pool.map(get, range(n)))
    assert codes == [200] * n and calls == 1


def _settle(cache: AuthCache, *, hang_s: float = 60.0) -> None:
    """Wait (in real time; the bound only ends a hang) until no background lookup runs."""
    t0 = time.monotonic()
    while cache.refreshing:
        assert time.monotonic() - t0 < hang_s, "a background lookup never ended"
        time.sleep(0.005)


def test_revocation_elsewhere_applies_within_the_ttl_with_refresh_ahead(
    client, headers, settings, monkeypatch
):
    # The cache's clock is stepped 50 ms per poll, after the lookups a poll started have
    # ended: the rule is checked, not how fast this machine answers.
    import backend.authcache

    clock = SteppedClock()
    monkeypatch.setattr(backend.authcache, "time", clock)
    hdr = headers["operator"]
    cache = client.app.state.runtime.auth_cache
    t0 = clock()
    while clock() - t0 < 1.5 * TTL_S:  # a busy console: its entry refreshed ahead
        assert client.get("/api/robot/state", headers=hdr).status_code == 200
        _settle(cache)
        clock.advance(0.05)
    assert cache.refreshes >= 1
    with sqlite3.connect(_db_file(settings)) as conn:
        conn.execute("UPDATE api_tokens SET revoked = 1")
    revoked = clock()
    while client.get("/api/robot/state", headers=hdr).status_code == 200:
        assert clock() - revoked < TTL_S, "signed in after the TTL"
        _settle(cache)
        clock.advance(0.05)
