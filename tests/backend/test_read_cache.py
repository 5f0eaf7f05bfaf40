"""The read cache of the hot list and status routes (``backend.readcache``): a write
through this process is visible to the next read, another process's within the TTL,
roles are checked per request and an entry is never served to a weaker role, the size is
bounded, and a read that raced a commit is not kept."""

from __future__ import annotations

import asyncio
import dataclasses
import gc
import logging
import sqlite3
import time

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import text, update

from backend.app import create_app
from backend.db.models import Cell, ObjectKind, ObjectModel, Role
from backend.db.session import Database
from backend.readcache import ALL_TABLES, MAX_REFRESHING, REFRESH_AHEAD_FRACTION, TTL_S, ReadCache
from tests.utils.clock import SteppedClock


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
    clock = SteppedClock()
    cache, reads = ReadCache(ttl_s=0.3, clock=clock), _Reads()
    assert _get(cache, "k", reads) == "v" and _get(cache, "k", reads) == "v"
    assert reads.calls == 1 and (cache.hits, cache.misses) == (1, 1)
    clock.advance(0.35)
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


def test_another_process_write_is_seen_within_the_ttl(
    client, headers, settings, monkeypatch
) -> None:
    # The cache's clock moves only when the test moves it: a stalled test process cannot
    # make the answer look older or younger than it is.
    import backend.readcache

    clock = SteppedClock()
    monkeypatch.setattr(backend.readcache, "time", clock)
    hdr = headers["viewer"]
    r = client.get("/api/cells", headers=hdr)
    assert r.status_code == 200 and r.json()["count"] >= 1
    # Another process (plain sqlite3, not this process's sessions): a second cell's row.
    with sqlite3.connect(_db_file(settings)) as conn:
        conn.execute("UPDATE cells SET description = 'renamed elsewhere'")
    clock.advance(TTL_S)
    r = client.get("/api/cells", headers=hdr)
    assert r.status_code == 200
    assert {c["description"] for c in r.json()["data"]} == {"renamed elsewhere"}


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


# -- refresh ahead ------------------------------------------------------------------------------
class _Gated:
    """A read answering ``v1``, ``v2``, ... that, from its second call on, waits for
    :attr:`gate` (a background re-read held in flight while the test looks)."""

    def __init__(self, *, fail: bool = False) -> None:
        self.calls = 0
        self.gate = asyncio.Event()
        self.fail = fail

    async def __call__(self) -> str:
        self.calls += 1
        n = self.calls
        if n > 1:
            await self.gate.wait()
        if self.fail:
            raise RuntimeError("database went away")
        return f"v{n}"


def _due_in(cache: ReadCache) -> float:
    """Seconds from an entry's read until a hit refreshes it (and a margin)."""
    return cache.ttl_s * (1.0 - REFRESH_AHEAD_FRACTION) + 0.02


@pytest.mark.parametrize("how", ["get_or_read", "peek"])
def test_refresh_ahead_serves_the_old_entry_and_replaces_it_without_a_wait(how) -> None:
    clock = SteppedClock()
    cache, reads = ReadCache(ttl_s=0.5, clock=clock), _Gated()

    async def hit() -> object:
        if how == "peek":  # the fast path's way in
            e = cache.peek("k", role=Role.viewer, tables=("cells",))
            return None if e is None else e.value
        return await cache.get_or_read("k", role=Role.viewer, tables=("cells",), read=reads)

    async def run() -> None:
        await cache.get_or_read("k", role=Role.viewer, tables=("cells",), read=reads)
        first = cache.peek("k", role=Role.viewer, tables=("cells",))
        assert first is not None and cache.refreshing == 0  # young: no refresh yet
        clock.advance(_due_in(cache))
        # Answered at once from the old entry (the re-read is held at its gate) ...
        assert await asyncio.wait_for(hit(), 0.05) == "v1"
        assert cache.refreshing == 1 and reads.calls == 2
        for _ in range(5):  # ... and only one re-read of the key, however many hits
            assert await hit() == "v1"
        assert cache.refreshing == 1 and reads.calls == 2 and cache.refreshes == 1
        reads.gate.set()
        while cache.refreshing:
            await asyncio.sleep(0.005)
        new = cache.peek("k", role=Role.viewer, tables=("cells",))
        assert new is not None and new.value == "v2" and new.until > first.until
        assert new.role is Role.viewer  # read for the role of the entry it replaced
        assert reads.calls == 2 and cache.misses == 1  # no request read

    asyncio.run(run())


def test_the_refresh_keeps_the_entry_s_role() -> None:
    clock = SteppedClock()
    cache, reads = ReadCache(ttl_s=0.3, clock=clock), _Gated()
    reads.gate.set()

    async def run() -> None:
        await cache.get_or_read("k", role=Role.operator, tables=("cells",), read=reads)
        clock.advance(_due_in(cache))
        # An engineer's hit refreshes it; the new entry is still the operator's.
        await cache.get_or_read("k", role=Role.engineer, tables=("cells",), read=reads)
        while cache.refreshing:
            await asyncio.sleep(0.005)
        assert cache.peek("k", role=Role.viewer, tables=("cells",)) is None
        e = cache.peek("k", role=Role.operator, tables=("cells",))
        assert e is not None and e.value == "v2" and e.role is Role.operator

    asyncio.run(run())


def test_background_re_reads_are_bounded() -> None:
    clock = SteppedClock()
    cache = ReadCache(ttl_s=0.5, clock=clock)
    reads = {k: _Gated() for k in range(MAX_REFRESHING + 3)}

    async def run() -> None:
        for k, read in reads.items():
            await cache.get_or_read(k, role=Role.viewer, tables=("cells",), read=read)
        clock.advance(_due_in(cache))
        for k in reads:
            assert cache.peek(k, role=Role.viewer, tables=("cells",)) is not None
        assert cache.refreshing == MAX_REFRESHING == cache.refreshes
        await asyncio.sleep(0.01)  # the re-reads run up to their gates
        assert sum(r.calls for r in reads.values()) == len(reads) + MAX_REFRESHING
        await cache.close()

    asyncio.run(run())


def test_an_entry_is_never_served_past_its_until_while_its_refresh_hangs() -> None:
    clock = SteppedClock()
    cache, reads = ReadCache(ttl_s=0.3, clock=clock), _Gated()

    async def run() -> None:
        await cache.get_or_read("k", role=Role.viewer, tables=("cells",), read=reads)
        e = cache.peek("k", role=Role.viewer, tables=("cells",))
        assert e is not None
        clock.advance(_due_in(cache))
        assert cache.peek("k", role=Role.viewer, tables=("cells",)) is e  # refresh started
        clock.advance(max(0.0, e.until - clock()) + 0.01)
        assert cache.peek("k", role=Role.viewer, tables=("cells",)) is None  # expired
        # A request now waits for the re-read in flight (shared), not the old answer.
        waiter = asyncio.create_task(
            cache.get_or_read("k", role=Role.viewer, tables=("cells",), read=reads)
        )
        await asyncio.sleep(0.02)
        assert not waiter.done() and cache.shared == 1
        reads.gate.set()
        assert await waiter == "v2" and reads.calls == 2

    asyncio.run(run())


def test_a_commit_during_a_refresh_is_not_overwritten_by_its_stale_read() -> None:
    clock = SteppedClock()
    cache, reads = ReadCache(ttl_s=0.5, clock=clock), _Gated()

    async def run() -> None:
        await cache.get_or_read("k", role=Role.viewer, tables=("cells",), read=reads)
        clock.advance(_due_in(cache))
        cache.peek("k", role=Role.viewer, tables=("cells",))
        assert cache.refreshing == 1
        assert cache.invalidate({"cells"}) == 1  # a commit wrote cells: the entry goes ...
        reads.gate.set()  # ... and the re-read that started before it finishes
        while cache.refreshing:
            await asyncio.sleep(0.005)
        assert cache.peek("k", role=Role.viewer, tables=("cells",)) is None  # not kept
        got = await cache.get_or_read("k", role=Role.viewer, tables=("cells",), read=reads)
        assert got == "v3"  # the next request reads after the commit

    asyncio.run(run())


def test_a_commit_through_a_session_during_a_refresh_wins(settings) -> None:
    clock = SteppedClock()
    cache = ReadCache(ttl_s=0.5, clock=clock)

    async def run() -> None:
        db = Database(settings.database_url)
        gate = asyncio.Event()

        async def describe() -> str:  # the cell's description, as a route would read it
            async with db.session() as s:
                got = await s.scalar(text("SELECT description FROM cells WHERE name = 'refreshed'"))
            await gate.wait()  # a commit lands after the read, before it is stored
            return str(got)

        try:
            async with db.session() as s:
                s.add(Cell(name="refreshed", description="as read"))
            gate.set()
            before = await cache.get_or_read(
                "d", role=Role.viewer, tables=("cells",), read=describe
            )
            gate.clear()
            clock.advance(_due_in(cache))
            cache.peek("d", role=Role.viewer, tables=("cells",))  # starts the re-read
            await asyncio.sleep(0.05)  # it has read the old description
            async with db.session() as s:
                await s.execute(update(Cell).values(description=f"{before}, changed"))
            gate.set()
            while cache.refreshing:
                await asyncio.sleep(0.005)
            got = await cache.get_or_read("d", role=Role.viewer, tables=("cells",), read=describe)
            assert before == "as read" and got == "as read, changed"
        finally:
            await cache.close()
            await db.dispose()

    asyncio.run(run())


def test_a_failed_refresh_is_logged_once_and_harmless(caplog) -> None:
    clock = SteppedClock()
    cache, reads = ReadCache(ttl_s=0.3, clock=clock), _Gated()
    reads.gate.set()
    unhandled: list[dict] = []

    async def run() -> None:
        asyncio.get_running_loop().set_exception_handler(lambda _loop, ctx: unhandled.append(ctx))
        for _ in range(2):  # two entries, each refreshed once; both re-reads fail
            reads.fail = False
            await cache.get_or_read("k", role=Role.viewer, tables=("cells",), read=reads)
            e = cache.peek("k", role=Role.viewer, tables=("cells",))
            assert e is not None
            clock.advance(_due_in(cache))
            reads.fail = True
            assert cache.peek("k", role=Role.viewer, tables=("cells",)) is e  # starts it
            while cache.refreshing:
                await asyncio.sleep(0.005)
            assert cache.peek("k", role=Role.viewer, tables=("cells",)) is e  # still served
            clock.advance(max(0.0, e.until - clock()) + 0.01)
            assert cache.peek("k", role=Role.viewer, tables=("cells",)) is None  # expired
        gc.collect()
        await asyncio.sleep(0)

    with caplog.at_level(logging.INFO, logger="backend.readcache"):
        asyncio.run(run())
    gc.collect()
    warnings = [r for r in caplog.records if r.levelno >= logging.WARNING]
    assert len(warnings) == 1 and "went away" in warnings[0].getMessage()
    # One re-read per entry (a failed one is not tried again on the entry's later hits).
    assert cache.refresh_failures == 2 and reads.calls == 4 and unhandled == []


def test_shutdown_leaves_no_background_read() -> None:
    clock = SteppedClock()
    cache, reads = ReadCache(ttl_s=0.3, clock=clock), _Gated()

    async def run() -> asyncio.Task[None]:
        await cache.get_or_read("k", role=Role.viewer, tables=("cells",), read=reads)
        clock.advance(_due_in(cache))
        cache.peek("k", role=Role.viewer, tables=("cells",))
        (task,) = cache._background.tasks
        await asyncio.sleep(0.01)  # the re-read waits at its gate
        await cache.close()  # the gate never opens: the re-read hangs until cancelled
        assert task.cancelled() and cache.refreshing == 0 and len(cache) == 0
        # Closed: a hit starts no re-read until the cache is opened again.
        await cache.get_or_read("k", role=Role.viewer, tables=("cells",), read=lambda: _v("w"))
        clock.advance(_due_in(cache))
        cache.peek("k", role=Role.viewer, tables=("cells",))
        assert cache.refreshing == 0
        cache.open()
        cache.peek("k", role=Role.viewer, tables=("cells",))
        assert cache.refreshing == 1
        await cache.close()
        return task

    asyncio.run(run())
    assert reads.calls == 2


async def _v(value: str) -> str:
    return value


def test_the_runtime_cancels_background_reads_before_the_engine_goes(
    settings, tokens, monkeypatch
) -> None:
    order: list[str] = []
    real_dispose = Database.dispose

    async def dispose(self: Database) -> None:
        order.append("dispose")
        await real_dispose(self)

    monkeypatch.setattr(Database, "dispose", dispose)
    app = create_app(settings)
    with TestClient(app) as client:
        rt = client.app.state.runtime

        async def hang() -> str:
            try:
                await asyncio.Event().wait()
            finally:
                order.append("re-read ended")
            return "never"

        async def start() -> None:
            await rt.read_cache.get_or_read("x", role=Role.viewer, tables=("cells",),
                                            read=lambda: _v("old"))  # fmt: skip
            e = rt.read_cache._entries["x"]
            rt.read_cache._entries["x"] = dataclasses.replace(e, until=time.monotonic() + 0.01,
                                                               read=hang)  # fmt: skip
            rt.read_cache.peek("x", role=Role.viewer, tables=("cells",))

        client.portal.call(start)
        assert rt.read_cache.refreshing == 1
    assert order[:2] == ["re-read ended", "dispose"] and rt.read_cache.refreshing == 0
