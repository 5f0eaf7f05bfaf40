"""The runtime's caches (``backend.caches``): a write noted by the service that makes it
invalidates at once, another process's write is seen within the TTL, a revocation applies
at once, roles are checked per request, sizes are bounded, and a read that raced a write
is not kept.  Every TTL is counted on a clock the test moves."""

from __future__ import annotations

import asyncio
import sqlite3
from datetime import timedelta

import pytest
from sqlalchemy import select

from backend.auth import create_user, revoke_tokens
from backend.caches import USERS, AuthCache, ReadCache, users_changed
from backend.db.models import Role, User
from backend.db.session import Database, changed
from backend.db.types import utcnow
from backend.knowntokens import KnownTokens
from tests.utils.caches import clocked_caches
from tests.utils.clock import SteppedClock

SECRET = "caches-secret-0123456789abcdef"


class _Reads:
    """A read that counts its calls and answers ``value``."""

    def __init__(self, value: object = "v") -> None:
        self.calls = 0
        self.value = value

    async def __call__(self) -> object:
        self.calls += 1
        return self.value


def _get(cache: ReadCache, key, reads, *, role=Role.viewer, topics=("object_models",)):
    return asyncio.run(cache.get_or_read(key, role=role, topics=topics, read=reads))


def _db_file(settings) -> str:
    return settings.database_url.split("///", 1)[1]


# -- the read cache on its own ----------------------------------------------------------------
def test_reuse_within_the_ttl_then_read_again() -> None:
    clock = SteppedClock()
    cache, reads = ReadCache(ttl_s=1.0, clock=clock), _Reads()
    assert _get(cache, "k", reads) == "v" and _get(cache, "k", reads) == "v"
    assert reads.calls == 1 and (cache.hits, cache.misses) == (1, 1)
    clock.advance(0.99)
    _get(cache, "k", reads)
    assert reads.calls == 1
    clock.advance(0.02)
    _get(cache, "k", reads)
    assert reads.calls == 2


def test_ttl_zero_turns_it_off() -> None:
    cache, reads = ReadCache(ttl_s=0.0), _Reads()
    for _ in range(3):
        _get(cache, "k", reads)
    assert reads.calls == 3 and len(cache) == 0


def test_an_answer_is_never_served_to_a_weaker_role() -> None:
    cache = ReadCache(ttl_s=10.0, clock=SteppedClock())
    eng, view = _Reads("engineer's"), _Reads("viewer's")
    assert _get(cache, "k", eng, role=Role.engineer) == "engineer's"
    assert _get(cache, "k", view, role=Role.viewer) == "viewer's"  # read again, for it
    assert _get(cache, "k", eng, role=Role.engineer) == "viewer's"  # a stronger role may
    assert (eng.calls, view.calls) == (1, 1)


def test_bounded_size_least_recently_used_first() -> None:
    cache = ReadCache(ttl_s=10.0, max_entries=3, clock=SteppedClock())
    reads = _Reads()
    for k in range(5):
        _get(cache, k, reads)
    assert len(cache) == 3 and reads.calls == 5
    _get(cache, 4, reads)  # kept
    _get(cache, 0, reads)  # went first
    assert reads.calls == 6


def test_invalidate_drops_only_answers_of_those_topics() -> None:
    cache = ReadCache(ttl_s=10.0, clock=SteppedClock())
    models, cells = _Reads(), _Reads()
    _get(cache, "m", models, topics=("object_models", "trained_views"))
    _get(cache, "c", cells, topics=("cells",))
    assert cache.invalidate({"trained_views"}) == 1
    _get(cache, "m", models, topics=("object_models", "trained_views"))
    _get(cache, "c", cells, topics=("cells",))
    assert (models.calls, cells.calls) == (2, 1)
    cache.clear()
    _get(cache, "c", cells, topics=("cells",))
    assert cells.calls == 2


def test_a_read_that_raced_a_write_is_not_kept() -> None:
    cache = ReadCache(ttl_s=10.0, clock=SteppedClock())
    n = 0

    async def read() -> int:
        nonlocal n
        n += 1
        if n == 1:
            cache.invalidate({"cells"})  # a write committed while the read was in flight
        return n

    async def run() -> list[int]:
        get = lambda: cache.get_or_read("k", role=Role.viewer, topics=("cells",), read=read)  # noqa: E731
        return [await get(), await get(), await get()]

    assert asyncio.run(run()) == [1, 2, 2]  # the first answer was not kept


def test_concurrent_misses_share_one_read_of_a_role_no_stronger_than_theirs() -> None:
    cache = ReadCache(ttl_s=10.0, clock=SteppedClock())
    calls: list[str] = []
    gate = asyncio.Event()

    async def slow(value: str) -> str:
        calls.append(value)
        await gate.wait()
        return value

    async def run() -> list[str]:
        def get(role: Role, value: str):
            return cache.get_or_read("k", role=role, topics=("cells",), read=lambda: slow(value))

        first = asyncio.create_task(get(Role.operator, "operator's"))
        await asyncio.sleep(0)  # its read is in flight
        rest = [
            asyncio.create_task(get(r, v))
            for r, v in ((Role.engineer, "e"), (Role.operator, "o"), (Role.viewer, "viewer's"))
        ]
        await asyncio.sleep(0)
        gate.set()
        return [await first, *[await t for t in rest]]

    got = asyncio.run(run())
    assert got == ["operator's", "operator's", "operator's", "viewer's"]
    assert sorted(calls) == ["operator's", "viewer's"]


def test_a_failed_read_fails_its_waiters_and_is_not_kept() -> None:
    cache = ReadCache(ttl_s=10.0, clock=SteppedClock())

    async def boom() -> str:
        await asyncio.sleep(0)
        raise RuntimeError("database down")

    async def run() -> list[object]:
        get = lambda: cache.get_or_read("k", role=Role.viewer, topics=("cells",), read=boom)  # noqa: E731
        return await asyncio.gather(get(), get(), return_exceptions=True)

    got = asyncio.run(run())
    assert [type(g) for g in got] == [RuntimeError, RuntimeError] and len(cache) == 0


def test_a_cancelled_reader_leaves_its_waiters_to_read_themselves() -> None:
    cache = ReadCache(ttl_s=10.0, clock=SteppedClock())
    calls = 0
    gate = asyncio.Event()

    async def slow() -> str:
        nonlocal calls
        calls += 1
        await gate.wait()
        return "v"

    async def run() -> str:
        get = lambda: cache.get_or_read("k", role=Role.viewer, topics=("cells",), read=slow)  # noqa: E731
        owner = asyncio.create_task(get())
        await asyncio.sleep(0)
        waiter = asyncio.create_task(get())
        await asyncio.sleep(0)
        owner.cancel()  # its client went away
        with pytest.raises(asyncio.CancelledError):
            await owner
        gate.set()
        return await waiter

    assert asyncio.run(run()) == "v" and calls == 2


@pytest.mark.parametrize("cache", [ReadCache, AuthCache])
def test_bad_arguments_are_refused(cache) -> None:
    for kwargs, err in (
        ({"ttl_s": -1.0}, ValueError),
        ({"ttl_s": 1e6}, ValueError),
        ({"ttl_s": True}, TypeError),
        ({"ttl_s": "1"}, TypeError),
        ({"max_entries": 0}, ValueError),
        ({"max_entries": 1.5}, TypeError),
    ):
        with pytest.raises(err):
            cache(**kwargs)
    with pytest.raises(TypeError):
        asyncio.run(ReadCache().get_or_read("k", role="viewer", topics=("x",), read=_Reads()))  # type: ignore[arg-type]
    with pytest.raises(ValueError):
        asyncio.run(ReadCache().get_or_read("k", role=Role.viewer, topics=(), read=_Reads()))


# -- the database tells the caches what its services wrote ----------------------------------
def test_a_session_s_noted_changes_reach_the_hooks_when_it_ends(settings) -> None:
    seen: list[dict] = []

    async def run() -> None:
        db = Database(settings.database_url)
        db.on_change.append(lambda c: seen.append(dict(c)))
        try:
            async with db.session() as s:  # a read notes nothing
                await s.scalar(select(User.id).limit(1))
            assert seen == []
            async with db.session() as s:
                changed(s, "cells")
                changed(s, USERS, [3])
                changed(s, USERS, [1])
                changed(s, "object_models", [5])
                changed(s, "object_models")  # any row beats some rows
            assert seen == [{"cells": None, USERS: frozenset({1, 3}), "object_models": None}]
            with pytest.raises(RuntimeError):
                async with db.session() as s:  # rolled back: dropping too much is harmless
                    changed(s, "cells")
                    raise RuntimeError("abort")
            assert seen[-1] == {"cells": None}
        finally:
            await db.dispose()

    asyncio.run(run())
    with pytest.raises(ValueError):
        changed(type("S", (), {"info": {}})(), "")


def test_the_services_note_what_they_write(settings) -> None:
    from backend.recognition import models as msvc

    cache = ReadCache(ttl_s=10.0, clock=SteppedClock())
    models, cells = _Reads(), _Reads()

    async def run() -> None:
        db = Database(settings.database_url)
        db.on_change.append(cache.on_change)

        async def both() -> None:
            topics = ("object_models", "trained_views")
            await cache.get_or_read("m", role=Role.viewer, topics=topics, read=models)
            await cache.get_or_read("c", role=Role.viewer, topics=("cells",), read=cells)

        try:
            await both()
            row = await msvc.create_model(db, msvc.ModelFields(name="noted", kind="2d"))
            await both()
            assert (models.calls, cells.calls) == (2, 1)
            await msvc.update_model(db, row.id, msvc.ModelFields(description="changed"))
            await both()
            await msvc.delete_model(db, row.id)
            await both()
            assert (models.calls, cells.calls) == (4, 1)
        finally:
            await db.dispose()

    asyncio.run(run())


# -- the sign-in cache ----------------------------------------------------------------------
def _lookup(user: User, expires_at=None, calls: list | None = None):
    async def lookup():
        if calls is not None:
            calls.append(1)
        return user, expires_at

    return lookup


def _user(uid: int = 7, role: str = "operator") -> User:
    return User(id=uid, name=f"u{uid}", role=role, disabled=False, created_at=utcnow())


def test_a_sign_in_is_reused_within_the_ttl_and_noted_for_the_emergency_stop() -> None:
    clock = SteppedClock()
    known = KnownTokens(clock=clock)
    cache, calls = AuthCache(ttl_s=2.0, clock=clock, known=known), []
    got = asyncio.run(cache.sign_in("h1", _lookup(_user(), calls=calls)))
    assert got is not None and got.name == "u7"
    assert asyncio.run(cache.sign_in("h1", _lookup(_user(), calls=calls))).role == "operator"
    assert len(calls) == 1 and cache.lookups == 1
    assert known.get("h1") is not None
    clock.advance(2.0)
    assert cache.get("h1") is None  # expired: the next request asks the database


def test_a_refused_sign_in_is_never_cached() -> None:
    cache = AuthCache(clock=SteppedClock())

    async def refused():
        return None

    assert asyncio.run(cache.sign_in("h", refused)) is None
    assert len(cache) == 0


def test_an_entry_past_its_token_s_expiry_is_not_served() -> None:
    cache = AuthCache(ttl_s=60.0, clock=SteppedClock())
    soon = utcnow() + timedelta(milliseconds=1)
    cache.put("h", _user(), soon, generation=cache.generation)
    past = utcnow() - timedelta(seconds=1)
    cache.put("g", _user(), past.replace(tzinfo=None), generation=cache.generation)  # naive
    assert cache.get("g") is None
    while utcnow() <= soon:
        pass
    assert cache.get("h") is None


def test_forgetting_users_drops_theirs_only_here_and_in_the_known_tokens() -> None:
    clock = SteppedClock()
    known = KnownTokens(clock=clock)
    cache = AuthCache(clock=clock, known=known)
    for h, uid in (("a", 1), ("b", 2), ("c", 2)):
        asyncio.run(cache.sign_in(h, _lookup(_user(uid))))
    cache.on_change({"cells": None})  # not a sign-in change
    assert len(cache) == 3
    cache.on_change({USERS: frozenset({2})})
    assert cache.get("a") is not None and cache.get("b") is None and cache.get("c") is None
    assert known.get("a") is not None and known.get("b") is None
    assert cache.forget_users(None) == 1 and len(known) == 0


def test_a_lookup_that_started_before_a_change_is_not_kept() -> None:
    cache = AuthCache(clock=SteppedClock(), known=KnownTokens())

    async def racing():
        cache.forget_users({7})  # the user's token revoked while the lookup was in flight
        return _user(7), None

    assert asyncio.run(cache.sign_in("h", racing)) is not None  # this request: as read
    assert cache.get("h") is None and cache.known is not None and len(cache.known) == 0


def test_concurrent_sign_ins_of_one_token_share_one_lookup() -> None:
    cache = AuthCache(clock=SteppedClock())
    gate, calls = asyncio.Event(), []

    async def slow():
        calls.append(1)
        await gate.wait()
        return _user(), None

    async def run() -> list:
        tasks = [asyncio.create_task(cache.sign_in("h", slow)) for _ in range(5)]
        await asyncio.sleep(0)
        gate.set()
        return [await t for t in tasks]

    users = asyncio.run(run())
    assert len(calls) == 1 and cache.shared == 4 and cache.lookups == 1
    assert all(u is not None and u.name == "u7" for u in users)
    assert len({id(u) for u in users}) == 5  # each request gets its own copy


def test_a_lookup_in_flight_before_a_change_is_not_shared_after_it() -> None:
    cache = AuthCache(clock=SteppedClock())
    gate, calls = asyncio.Event(), []

    async def slow():
        calls.append(1)
        await gate.wait()
        return _user(), None

    async def run() -> None:
        first = asyncio.create_task(cache.sign_in("h", slow))
        await asyncio.sleep(0)
        cache.forget_users({7})  # the user changed while the first lookup ran
        second = asyncio.create_task(cache.sign_in("h", slow))
        await asyncio.sleep(0)
        gate.set()
        await asyncio.gather(first, second)

    asyncio.run(run())
    assert len(calls) == 2 and cache.shared == 0


def test_a_refused_lookup_is_shared_but_never_cached() -> None:
    cache = AuthCache(clock=SteppedClock())
    gate, calls = asyncio.Event(), []

    async def refused():
        calls.append(1)
        await gate.wait()
        return None

    async def run() -> list:
        tasks = [asyncio.create_task(cache.sign_in("h", refused)) for _ in range(3)]
        await asyncio.sleep(0)
        gate.set()
        return [await t for t in tasks]

    assert asyncio.run(run()) == [None, None, None] and len(calls) == 1 and len(cache) == 0


def test_the_sign_in_cache_is_bounded() -> None:
    cache = AuthCache(max_entries=2, clock=SteppedClock())
    for h in ("a", "b", "c"):
        cache.put(h, _user(), None, generation=cache.generation)
    assert len(cache) == 2 and cache.get("a") is None


def test_revoking_through_the_service_forgets_the_user(settings) -> None:
    cache = AuthCache(ttl_s=60.0, clock=SteppedClock())

    async def run() -> None:
        db = Database(settings.database_url)
        db.on_change.append(cache.on_change)
        try:
            async with db.session() as s:
                user, _tok = await create_user(s, "revoked-one", Role.operator, SECRET)
            cache.put("h", user, None, generation=cache.generation)
            async with db.session() as s:
                assert await revoke_tokens(s, await s.get_one(User, user.id)) == 1
            assert cache.get("h") is None
            cache.put("h", user, None, generation=cache.generation)
            async with db.session() as s:  # nothing left to revoke: nothing changed
                assert await revoke_tokens(s, await s.get_one(User, user.id)) == 0
            assert cache.get("h") is not None
            async with db.session() as s:
                await users_changed(s, None)
            assert cache.get("h") is None
        finally:
            await db.dispose()

    asyncio.run(run())


# -- through the API ------------------------------------------------------------------------
def test_a_write_through_the_api_is_visible_to_the_next_read(client, headers) -> None:
    names = lambda r: {m["name"] for m in r.json()["data"]}  # noqa: E731
    rt = client.app.state.runtime
    clocked_caches(rt, SteppedClock(), read_ttl_s=10.0)  # only the write can make it fresh
    r = client.get("/api/models", headers=headers["viewer"])
    assert r.status_code == 200 and "fresh-one" not in names(r)
    hits = rt.read_cache.hits
    assert client.get("/api/models", headers=headers["viewer"]).status_code == 200
    assert rt.read_cache.hits == hits + 1  # served from the cache
    r = client.post("/api/models", headers=headers["engineer"],
                    json={"name": "fresh-one", "kind": "2d"})  # fmt: skip
    assert r.status_code == 201, r.text
    r = client.get("/api/models", headers=headers["viewer"])
    assert r.status_code == 200 and "fresh-one" in names(r)
    model_id = next(m["id"] for m in r.json()["data"] if m["name"] == "fresh-one")
    assert client.delete(f"/api/models/{model_id}", headers=headers["engineer"]).status_code == 204
    r = client.get("/api/models", headers=headers["viewer"])
    assert "fresh-one" not in names(r) and r.json()["count"] == len(r.json()["data"])


def test_another_process_write_is_seen_within_the_ttl(client, headers, settings) -> None:
    clock = SteppedClock()
    clocked_caches(client.app.state.runtime, clock, read_ttl_s=1.0)
    hdr = headers["viewer"]
    r = client.get("/api/cells", headers=hdr)
    assert r.status_code == 200 and r.json()["count"] >= 1
    with sqlite3.connect(_db_file(settings)) as conn:  # another process, not this one's
        conn.execute("UPDATE cells SET description = 'renamed elsewhere'")
    r = client.get("/api/cells", headers=hdr)
    assert {c["description"] for c in r.json()["data"]} != {"renamed elsewhere"}
    clock.advance(1.0)
    r = client.get("/api/cells", headers=hdr)
    assert r.status_code == 200
    assert {c["description"] for c in r.json()["data"]} == {"renamed elsewhere"}


def test_roles_are_checked_per_request_with_a_warm_cache(client, headers) -> None:
    for route in ("/api/models", "/api/cells", "/api/inspections?limit=20", "/api/status"):
        assert client.get(route, headers=headers["viewer"]).status_code == 200
        r = client.get(route)  # no token: refused although the answer is cached
        assert r.status_code == 401 and r.json()["error"] == "unauthorized", route
    r = client.get("/api/models", headers={"Authorization": "Bearer vc_not-a-token"})
    assert r.status_code == 401


def test_revocation_here_applies_at_once(client, headers) -> None:
    rt = client.app.state.runtime
    clocked_caches(rt, SteppedClock(), auth_ttl_s=60.0)  # only the change can drop the entry
    hdr = headers["viewer"]
    assert client.get("/api/cells", headers=hdr).status_code == 200
    assert len(rt.auth_cache) >= 1  # the sign-in is cached
    r = client.delete("/api/users/test-viewer", headers=headers["engineer"])
    assert r.status_code == 200, r.text
    r = client.get("/api/cells", headers=hdr)
    assert r.status_code == 401 and r.json()["error"] == "unauthorized"


def test_a_revoked_token_and_a_role_change_apply_at_once(client, headers) -> None:
    rt = client.app.state.runtime
    clocked_caches(rt, SteppedClock(), auth_ttl_s=60.0)
    eng, op = headers["engineer"], headers["operator"]
    assert client.get("/api/users/me", headers=op).json()["role"] == "operator"
    r = client.patch("/api/users/test-operator", headers=eng, json={"role": "viewer"})
    assert r.status_code == 200, r.text
    assert client.get("/api/users/me", headers=op).json()["role"] == "viewer"
    tokens = client.get("/api/users/test-operator/tokens", headers=eng).json()["data"]
    for t in tokens:
        r = client.delete(f"/api/users/test-operator/tokens/{t['id']}", headers=eng)
        assert r.status_code == 200, r.text
    assert client.get("/api/users/me", headers=op).status_code == 401


def test_revocation_elsewhere_applies_within_the_ttl(client, headers, settings) -> None:
    clock = SteppedClock()
    clocked_caches(client.app.state.runtime, clock, auth_ttl_s=2.0)
    hdr = headers["operator"]
    assert client.get("/api/robot/state", headers=hdr).status_code == 200
    with sqlite3.connect(_db_file(settings)) as conn:  # another process revokes every token
        conn.execute("UPDATE api_tokens SET revoked = 1")
    assert client.get("/api/robot/state", headers=hdr).status_code == 200  # still cached
    clock.advance(2.0)
    assert client.get("/api/robot/state", headers=hdr).status_code == 401
