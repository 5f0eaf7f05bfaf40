"""The read cache of the hot list and status routes (``backend.readcache``): a write
through this process is visible to the next read, another process's within the TTL,
roles are checked per request and an entry is never served to a weaker role, the size is
bounded, and a read that raced a commit is not kept."""

from __future__ import annotations

import asyncio
import sqlite3
import time

import pytest
from sqlalchemy import text, update

from backend.db.models import Cell, ObjectKind, ObjectModel, Role
from backend.db.session import Database
from backend.readcache import ALL_TABLES, TTL_S, ReadCache


def _db_file(settings) -> str:
    return settings.database_url.split("///", 1)[1]


class _Reads:
    """A read that counts its calls and answers ``value``."""

    def __init__(self, value: object = "v") -> None:
        self.calls = 0
        self.value = value

    async def __call__(self) -> object:
        self.calls += 1
        return self.value


def _get(cache: ReadCache, key, reads: _Reads, *, role=Role.viewer, tables=("object_models",)):
    return asyncio.run(cache.get_or_read(key, role=role, tables=tables, read=reads))


# -- the cache on its own -------------------------------------------------------------------
def test_reuse_within_the_ttl_then_read_again() -> None:
    cache, reads = ReadCache(ttl_s=0.3), _Reads()
    assert _get(cache, "k", reads) == "v" and _get(cache, "k", reads) == "v"
    assert reads.calls == 1 and (cache.hits, cache.misses) == (1, 1)
    time.sleep(0.35)
    _get(cache, "k", reads)
    assert reads.calls == 2


def test_ttl_zero_turns_it_off() -> None:
    cache, reads = ReadCache(ttl_s=0.0), _Reads()
    for _ in range(3):
        _get(cache, "k", reads)
    assert reads.calls == 3 and len(cache) == 0


def test_an_entry_is_never_served_to_a_weaker_role() -> None:
    cache, reads = ReadCache(ttl_s=10.0), _Reads()
    _get(cache, "k", reads, role=Role.engineer)
    _get(cache, "k", reads, role=Role.viewer)  # read again, not served the engineer's
    assert reads.calls == 2
    _get(cache, "k", reads, role=Role.operator)  # the viewer's answer is fine for more
    assert reads.calls == 2
    with pytest.raises(TypeError, match="Role"):
        _get(cache, "k", reads, role="engineer")


def test_bounded_size_oldest_first() -> None:
    cache, reads = ReadCache(ttl_s=10.0, max_entries=3), _Reads()
    for k in range(5):
        _get(cache, k, reads)
    assert len(cache) == 3
    _get(cache, 4, reads)  # still there
    assert reads.calls == 5
    _get(cache, 0, reads)  # dropped: read again
    assert reads.calls == 6


def test_invalidate_drops_only_entries_of_those_tables() -> None:
    cache = ReadCache(ttl_s=10.0)
    models, cells = _Reads(), _Reads()
    _get(cache, "m", models, tables=("object_models", "trained_views"))
    _get(cache, "c", cells, tables=("cells",))
    assert cache.invalidate({"trained_views"}) == 1
    _get(cache, "m", models, tables=("object_models", "trained_views"))
    _get(cache, "c", cells, tables=("cells",))
    assert (models.calls, cells.calls) == (2, 1)
    assert cache.invalidate({ALL_TABLES}) == 2 and len(cache) == 0


def test_a_read_that_raced_a_write_is_not_kept() -> None:
    cache = ReadCache(ttl_s=10.0)
    calls = 0

    async def read_while_someone_writes() -> str:
        nonlocal calls
        calls += 1
        cache.invalidate({"cells"})  # a commit lands while the read is in flight
        return "old"

    async def run() -> None:
        for _ in range(2):
            await cache.get_or_read("k", role=Role.viewer, tables=("cells",),
                                    read=read_while_someone_writes)  # fmt: skip

    asyncio.run(run())
    assert calls == 2 and len(cache) == 0


def test_bad_arguments_are_refused() -> None:
    for kw, exc in (
        ({"ttl_s": -1.0}, ValueError), ({"ttl_s": float("nan")}, ValueError),
        ({"ttl_s": 11.0}, ValueError), ({"ttl_s": True}, TypeError),
        ({"max_entries": 0}, ValueError), ({"max_entries": 2.5}, TypeError),
    ):  # fmt: skip
        with pytest.raises(exc):
            ReadCache(**kw)
    cache = ReadCache()
    with pytest.raises(ValueError, match="tables"):
        _get(cache, "k", _Reads(), tables=())
    with pytest.raises(TypeError):
        _get(cache, ["unhashable"], _Reads())


# -- invalidation by this process's commits (SQLAlchemy session events) ----------------------
def test_commits_invalidate_the_tables_they_wrote_and_rollbacks_nothing(settings) -> None:
    cache = ReadCache(ttl_s=10.0)
    models, cells = _Reads(), _Reads()

    async def run() -> None:
        db = Database(settings.database_url)
        try:

            async def both() -> None:
                await cache.get_or_read(
                    "m", role=Role.viewer, tables=("object_models",), read=models
                )
                await cache.get_or_read("c", role=Role.viewer, tables=("cells",), read=cells)  # fmt: skip

            await both()
            async with db.session() as s:  # an ORM insert
                s.add(ObjectModel(name="cached-1", kind=ObjectKind("2d")))
            await both()
            assert (models.calls, cells.calls) == (2, 1)
            with pytest.raises(RuntimeError):
                async with db.session() as s:  # rolled back: nothing changed
                    s.add(ObjectModel(name="cached-2", kind=ObjectKind("2d")))
                    await s.flush()
                    raise RuntimeError("abort")
            await both()
            assert (models.calls, cells.calls) == (2, 1)
            async with db.session() as s:  # a bulk update names its table
                await s.execute(update(Cell).values(description="x"))
            await both()
            assert (models.calls, cells.calls) == (2, 2)
            async with db.session() as s:  # a textual write: its table is not known
                await s.execute(text("UPDATE cells SET description = 'y'"))
            await both()
            assert (models.calls, cells.calls) == (3, 3)
            async with db.session() as s:  # reads commit too, and invalidate nothing
                await s.scalar(text("SELECT count(*) FROM cells"))
                await s.get(Cell, 1)
            await both()
            assert (models.calls, cells.calls) == (3, 3)
        finally:
            await db.dispose()

    asyncio.run(run())


# -- through the API ------------------------------------------------------------------------
def test_a_write_through_the_api_is_visible_to_the_next_read(client, headers) -> None:
    names = lambda r: {m["name"] for m in r.json()["data"]}  # noqa: E731
    cache = client.app.state.runtime.read_cache
    cache.ttl_s = 10.0  # only the commit, not the expiry, can make the next read fresh
    r = client.get("/api/models", headers=headers["viewer"])
    assert r.status_code == 200 and "fresh-one" not in names(r)
    hits = cache.hits
    assert client.get("/api/models", headers=headers["viewer"]).status_code == 200
    assert cache.hits == hits + 1  # served from the cache
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
    hdr = headers["viewer"]
    r = client.get("/api/cells", headers=hdr)
    assert r.status_code == 200 and r.json()["count"] >= 1
    # Another process (plain sqlite3, not this process's sessions): a second cell's row.
    with sqlite3.connect(_db_file(settings)) as conn:
        conn.execute("UPDATE cells SET description = 'renamed elsewhere'")
    t0 = time.monotonic()
    while True:
        r = client.get("/api/cells", headers=hdr)
        assert r.status_code == 200
        if {c["description"] for c in r.json()["data"]} == {"renamed elsewhere"}:
            break
        assert time.monotonic() - t0 < TTL_S + 5.0, "still the old answer long after the TTL"
        time.sleep(0.05)


def test_roles_are_checked_per_request_with_a_warm_cache(client, headers) -> None:
    for route in ("/api/models", "/api/cells", "/api/inspections?limit=20", "/api/status"):
        assert client.get(route, headers=headers["viewer"]).status_code == 200
        r = client.get(route)  # no token: refused although the answer is cached
        assert r.status_code == 401 and r.json()["error"] == "unauthorized", route
    # (Few bad tokens: the sign-in throttle answers 429 after a handful.)
    r = client.get("/api/models", headers={"Authorization": "Bearer vc_not-a-token"})
    assert r.status_code == 401
    # A revoked user is refused at once, whatever the cache holds.
    assert client.get("/api/cells", headers=headers["viewer"]).status_code == 200
    r = client.delete("/api/users/test-viewer", headers=headers["engineer"])
    assert r.status_code in (200, 204), r.text
    r = client.get("/api/cells", headers=headers["viewer"])
    assert r.status_code == 401 and r.json()["error"] == "unauthorized"


# -- one read per key at a time ---------------------------------------------------------------
def test_concurrent_misses_share_one_read_of_a_role_no_stronger_than_theirs() -> None:
    cache = ReadCache(ttl_s=10.0)
    calls = []

    async def slow(value: str) -> str:
        calls.append(value)
        await asyncio.sleep(0.05)
        return value

    async def run() -> list[str]:
        def get(role: Role, value: str):
            return cache.get_or_read("k", role=role, tables=("cells",),
                                     read=lambda: slow(value))  # fmt: skip

        first = asyncio.create_task(get(Role.operator, "operator's"))
        await asyncio.sleep(0)  # its read is in flight
        rest = [get(Role.engineer, "e"), get(Role.operator, "o"), get(Role.viewer, "viewer's")]
        got = await asyncio.gather(*rest)  # while the first read is still in flight
        return [await first, *got]

    got = asyncio.run(run())
    # The engineer and the operator shared the operator's read; the viewer read its own.
    assert got == ["operator's", "operator's", "operator's", "viewer's"]
    assert sorted(calls) == ["operator's", "viewer's"]
    assert (cache.shared, cache.hits, cache.misses) == (2, 0, 2)


def test_a_failed_read_fails_its_waiters_and_is_not_kept() -> None:
    cache = ReadCache(ttl_s=10.0)

    async def boom() -> str:
        await asyncio.sleep(0.02)
        raise RuntimeError("database down")

    async def run() -> list[object]:
        get = lambda: cache.get_or_read("k", role=Role.viewer, tables=("cells",), read=boom)  # noqa: E731
        return await asyncio.gather(get(), get(), return_exceptions=True)

    got = asyncio.run(run())
    assert [type(g) for g in got] == [RuntimeError, RuntimeError] and len(cache) == 0


def test_a_cancelled_reader_leaves_its_waiters_to_read_themselves() -> None:
    cache = ReadCache(ttl_s=10.0)
    calls = 0

    async def slow() -> str:
        nonlocal calls
        calls += 1
        await asyncio.sleep(0.1)
        return "v"

    async def run() -> str:
        get = lambda: cache.get_or_read("k", role=Role.viewer, tables=("cells",), read=slow)  # noqa: E731
        owner = asyncio.create_task(get())
        await asyncio.sleep(0)
        waiter = asyncio.create_task(get())
        await asyncio.sleep(0.02)
        owner.cancel()  # its client went away
        with pytest.raises(asyncio.CancelledError):
            await owner
        return await waiter

    assert asyncio.run(run()) == "v" and calls == 2
