"""The fast path of the hot reads (``backend.api.fastpath``): byte for byte the answer and
headers of the normal path; only for a sign-in the cache holds valid (a revoked or expired
token, a blocked address and a weaker role get the normal path's refusal); a write through
the API is visible to the next read; the setting off leaves every request to FastAPI."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Iterator
from datetime import UTC, datetime, timedelta
from typing import Any

import pytest
from fastapi import FastAPI
from fastapi.testclient import TestClient
from sqlalchemy import select

from backend.api import FAST_READS
from backend.api.deps import EngineerUser, SessionDep, ViewerUser, install_runtime, runtime_of
from backend.api.fastpath import FastRead, FastReads, FastRequest, Fresh, fast_reads_of
from backend.app import create_app
from backend.auth import issue_token
from backend.db.models import User
from backend.db.session import Database
from backend.db.types import utcnow
from backend.inspection.results import InspectionRecord, store
from tests.utils.caches import clocked_caches
from tests.utils.clock import SteppedClock
from tests.utils.factories import make_settings, make_tokens, migrate

#: Every route the fast path answers, as the console asks it (query strings included).
ROUTES = (
    "/api/health",
    "/api/status",
    "/api/robot/state",
    "/api/camera/status",
    "/api/camera/frame.jpg",
    "/api/jobs?limit=20",
    "/api/jobs",
    "/api/cells",
    "/api/cells?limit=1&offset=0",
    "/api/inspections?limit=20",
    "/api/inspections?decision=unknown&since=2026-01-01T00:00:00Z",
    "/api/models",
    "/api/models?part=valve&limit=5",
)
NORMAL = {"X-Path": "normal"}


@contextlib.contextmanager
def _both_paths(settings) -> Iterator[tuple[TestClient, FastAPI]]:
    """One client over two apps serving one cell: the app as built (fast path on), and,
    for requests sent with ``X-Path: normal``, the same app built with the setting off."""
    fast = create_app(settings)
    normal = create_app(settings.model_copy(update={"fast_reads": False}))
    assert fast_reads_of(normal) is None

    async def both(scope: Any, receive: Any, send: Any) -> None:
        if scope["type"] == "http" and (b"x-path", b"normal") in scope["headers"]:
            install_runtime(normal, runtime_of(fast))
            await normal(scope, receive, send)
            return
        await fast(scope, receive, send)

    with TestClient(both) as c:
        yield c, fast


def _freeze(monkeypatch, rt) -> None:
    """Hold the cell's moving parts still (state stamps, camera frames), so that two
    requests one after the other see the same state; both paths read these."""
    cell = rt.cell
    state, status, jpeg = cell.driver.state, cell.camera_status(), cell.latest_jpeg()
    assert jpeg is not None
    monkeypatch.setattr(type(cell.driver), "state", property(lambda self: state))
    monkeypatch.setattr(cell, "camera_status", lambda: status)

    async def latest_jpeg_async(*, quality: int = 80) -> bytes:
        return jpeg

    monkeypatch.setattr(cell, "latest_jpeg_async", latest_jpeg_async)


def _some_rows(c: TestClient, rt, headers) -> None:
    """A model, a finished job and two inspections, so that the lists are not empty."""
    r = c.post("/api/models", headers=headers["engineer"],
               json={"name": "valve-block", "part": "valve", "kind": "2d"})  # fmt: skip
    assert r.status_code == 201, r.text
    r = c.post("/api/robot/home?wait=true", headers=headers["operator"])
    assert r.status_code == 200, r.text
    t = datetime(2026, 3, 1, tzinfo=UTC)
    for dec in ("recognized", "unknown"):
        rec = InspectionRecord(started_at=t, finished_at=t, decision=dec, reason="test",
                               policy="top-only", model_name="valve-block", score=0.7)  # fmt: skip
        c.portal.call(store, rt.database, rt.cell_id, rec)


@pytest.mark.parametrize("origin", [None, "https://hmi.plant.local"])
def test_both_paths_give_the_same_bytes_and_headers(tmp_path, monkeypatch, origin) -> None:
    settings = make_settings(tmp_path, cors_origins=["https://hmi.plant.local"])
    migrate(settings)
    hdr = {role: {"Authorization": f"Bearer {t}"} for role, t in make_tokens(settings).items()}
    with _both_paths(settings) as (c, app):
        rt = runtime_of(app)
        layer = fast_reads_of(app)
        assert layer is not None and layer.paths == {r.split("?")[0] for r in ROUTES}
        clocked_caches(rt, SteppedClock(), read_ttl_s=10.0)  # no answer expires meanwhile
        _some_rows(c, rt, hdr)
        _freeze(monkeypatch, rt)
        h = {**hdr["viewer"], **({"Origin": origin} if origin else {})}
        for route in ROUTES:
            assert c.get(route, headers=h).status_code == 200  # reads and caches
            answered = layer.answered
            a = c.get(route, headers=h)
            assert layer.answered == answered + 1, f"{route}: not answered by the fast path"
            b = c.get(route, headers={**h, **NORMAL})
            assert layer.answered == answered + 1, f"{route}: the normal path was not taken"
            assert a.status_code == b.status_code == 200, route
            assert a.content == b.content, route
            assert a.headers.raw == b.headers.raw, route
            if origin:
                assert a.headers["access-control-allow-origin"] == origin
        body = c.get("/api/models?part=valve&limit=5", headers=h).json()
        assert [m["name"] for m in body["data"]] == ["valve-block"]
        body = c.get("/api/inspections?limit=20", headers=h).json()
        assert body["count"] == 2 and len(body["data"]) == 2
        assert c.get("/api/jobs", headers=h).json()["count"] >= 1


def test_a_revoked_token_is_refused_on_the_fast_path(client, headers) -> None:
    layer = fast_reads_of(client.app)
    hdr = headers["viewer"]
    for _ in range(2):
        assert client.get("/api/cells", headers=hdr).status_code == 200
    answered = layer.answered
    assert client.get("/api/robot/state", headers=hdr).status_code == 200
    assert layer.answered == answered + 1  # the sign-in came from the cache
    r = client.delete("/api/users/test-viewer", headers=headers["engineer"])
    assert r.status_code in (200, 204), r.text
    for route in ("/api/cells", "/api/robot/state", "/api/status"):
        r = client.get(route, headers=hdr)
        assert r.status_code == 401, route
        assert r.json() == {"error": "unauthorized", "detail": "invalid, expired or revoked token"}
        assert r.headers["www-authenticate"] == "Bearer"
        assert r.headers["x-content-type-options"] == "nosniff"


async def _short_lived_token(url: str, secret: str, seconds: float) -> str:
    db = Database(url)
    try:
        async with db.session() as s:
            user = await s.scalar(select(User).where(User.name == "test-viewer"))
            assert user is not None
            return await issue_token(
                s, user, secret, expires_at=utcnow() + timedelta(seconds=seconds)
            )
    finally:
        await db.dispose()


def test_an_expired_token_is_refused_on_the_fast_path(client, settings, monkeypatch) -> None:
    import backend.auth
    import backend.caches

    rt = runtime_of(client.app)
    clocked_caches(rt, SteppedClock(), auth_ttl_s=60.0)  # only the token's expiry ends it
    layer = fast_reads_of(client.app)
    secret = settings.secret_key.get_secret_value()
    token = asyncio.run(_short_lived_token(settings.database_url, secret, 1.5))
    hdr = {"Authorization": f"Bearer {token}"}
    # The sign-in's "now" (the database's and the cache's expiry checks) stands still until
    # the test moves it past the expiry: a slow machine cannot expire the token early.
    now = [utcnow()]
    monkeypatch.setattr(backend.auth, "utcnow", lambda: now[0])
    monkeypatch.setattr(backend.caches, "utcnow", lambda: now[0])
    assert client.get("/api/robot/state", headers=hdr).status_code == 200
    answered = layer.answered
    assert client.get("/api/robot/state", headers=hdr).status_code == 200
    assert layer.answered == answered + 1
    now[0] += timedelta(seconds=1.6)
    r = client.get("/api/robot/state", headers=hdr)
    assert r.status_code == 401
    assert r.json() == {"error": "unauthorized", "detail": "invalid, expired or revoked token"}


def test_a_blocked_address_is_refused_even_with_a_cached_sign_in(client, headers) -> None:
    hdr = headers["viewer"]
    assert client.get("/api/robot/state", headers=hdr).status_code == 200
    assert client.get("/api/robot/state", headers=hdr).status_code == 200  # cached
    bad = {"Authorization": "Bearer vc_not-a-real-token"}
    codes = [client.get("/api/robot/state", headers=bad).status_code for _ in range(5)]
    assert codes[:4] == [401] * 4
    r = client.get("/api/robot/state", headers=hdr)
    assert r.status_code == 429 and r.json()["error"] == "too_many_attempts"
    assert int(r.headers["retry-after"]) >= 1


def test_the_routes_own_role_rule_applies(settings, tokens) -> None:
    app = create_app(settings.model_copy(update={"fast_reads": False}))

    @app.get("/api/test/engineers-only")
    async def read_engineers_only(_: EngineerUser) -> dict[str, int]:
        return {"answer": 42}

    async def fast_engineers_only(req: FastRequest) -> Fresh | None:
        return Fresh.of_content({"answer": 42})

    reads = [FastRead(read_engineers_only, fast_engineers_only)]
    app.add_middleware(FastReads, routes=app.routes, reads=reads)
    auth = {role: {"Authorization": f"Bearer {tok}"} for role, tok in tokens.items()}
    with TestClient(app) as c:
        layer = fast_reads_of(app)
        assert layer is not None
        for role in ("engineer", "viewer", "operator"):
            for _ in range(3):  # the sign-in is cached after the first
                r = c.get("/api/test/engineers-only", headers=auth[role])
                if role == "engineer":
                    assert r.status_code == 200 and r.json() == {"answer": 42}
                else:
                    assert r.status_code == 403, role
                    assert r.json() == {
                        "error": "forbidden",
                        "detail": f"this needs the engineer role; user 'test-{role}' is {role}",
                    }
        assert layer.answered == 2  # the engineer's second and third
        assert layer.passed == 1 + 3 + 3


def test_a_viewer_is_not_served_an_entry_read_for_an_engineer(client, headers) -> None:
    layer = fast_reads_of(client.app)
    clocked_caches(client.app.state.runtime, SteppedClock(), read_ttl_s=10.0)
    assert client.get("/api/robot/state", headers=headers["viewer"]).status_code == 200
    assert client.get("/api/cells", headers=headers["engineer"]).status_code == 200
    assert client.get("/api/cells", headers=headers["engineer"]).status_code == 200
    answered, passed = layer.answered, layer.passed
    # The read-cache entry may not answer a weaker role: the normal path reads again.
    assert client.get("/api/cells", headers=headers["viewer"]).status_code == 200
    assert (layer.answered, layer.passed) == (answered, passed + 1)


def test_a_write_through_the_api_is_visible_to_the_next_read(client, headers) -> None:
    names = lambda r: {m["name"] for m in r.json()["data"]}  # noqa: E731
    layer = fast_reads_of(client.app)
    clocked_caches(client.app.state.runtime, SteppedClock(), read_ttl_s=10.0)  # only the write
    hdr = headers["viewer"]
    for _ in range(2):
        r = client.get("/api/models", headers=hdr)
        assert r.status_code == 200 and "fresh-one" not in names(r)
    r = client.post("/api/models", headers=headers["engineer"],
                    json={"name": "fresh-one", "kind": "2d"})  # fmt: skip
    assert r.status_code == 201, r.text
    r = client.get("/api/models", headers=hdr)
    assert r.status_code == 200 and "fresh-one" in names(r)
    answered = layer.answered
    r = client.get("/api/models", headers=hdr)  # the new entry, from the fast path
    assert "fresh-one" in names(r) and layer.answered == answered + 1
    model_id = next(m["id"] for m in r.json()["data"] if m["name"] == "fresh-one")
    # A change of the live index alone (no commit) shows at once too.
    live = client.app.state.runtime.live_index
    live.drop_model(model_id)
    r = client.get("/api/models", headers=hdr)
    assert next(m for m in r.json()["data"] if m["id"] == model_id)["indexed_views"] == 0
    assert client.delete(f"/api/models/{model_id}", headers=headers["engineer"]).status_code == 204
    r = client.get("/api/models", headers=hdr)
    assert "fresh-one" not in names(r)


def test_bad_queries_and_missing_tokens_get_the_normal_answers(client, headers) -> None:
    layer = fast_reads_of(client.app)
    hdr = headers["viewer"]
    assert client.get("/api/jobs?limit=20", headers=hdr).status_code == 200
    passed = layer.passed
    r = client.get("/api/jobs?limit=0", headers=hdr)
    assert r.status_code == 422 and r.json()["error"] == "validation_error"
    assert "limit" in r.json()["detail"]
    r = client.get("/api/inspections?decision=maybe", headers=hdr)
    assert r.status_code == 422 and r.json()["error"] == "validation_error"
    r = client.get("/api/jobs?limit=20")
    assert r.status_code == 401 and r.json()["error"] == "unauthorized"
    r = client.get("/api/jobs?limit=20", headers={"Authorization": "Basic dXNlcjpwdw=="})
    assert r.status_code == 401
    assert layer.passed == passed + 4
    r = client.post("/api/jobs", headers=hdr)  # not a GET: FastAPI's 405
    assert r.status_code == 405


def test_the_setting_off_gives_the_old_path(tmp_path, tokens, settings) -> None:
    app = create_app(settings.model_copy(update={"fast_reads": False}))
    with TestClient(app) as c:
        assert fast_reads_of(app) is None
        hdr = {"Authorization": f"Bearer {tokens['viewer']}"}
        for route in ROUTES:
            assert c.get(route, headers=hdr).status_code == 200, route
    app = create_app(settings)
    with TestClient(app) as c:
        layer = fast_reads_of(app)
        assert layer is not None
        for route in ROUTES[:3]:
            for _ in range(2):
                assert c.get(route, headers=hdr).status_code == 200
        assert layer.answered >= 3


def test_routes_the_fast_path_cannot_answer_safely_are_refused(settings) -> None:
    app = FastAPI()

    @app.get("/a")
    async def read_a(_: ViewerUser, session: SessionDep) -> dict[str, int]:
        return {}

    @app.get("/b")
    async def read_b_first(_: ViewerUser) -> dict[str, int]:
        return {}

    @app.get("/b")
    async def read_b_second(_: ViewerUser) -> dict[str, int]:
        return {}

    async def answer(req: FastRequest) -> Fresh | None:
        return None

    async def inner(scope: Any, receive: Any, send: Any) -> None:
        raise AssertionError("never called")

    with pytest.raises(ValueError, match="not one the fast path knows"):
        FastReads(inner, routes=app.routes, reads=[FastRead(read_a, answer)])
    with pytest.raises(ValueError, match="answered by another route first"):
        FastReads(inner, routes=app.routes, reads=[FastRead(read_b_second, answer)])
    # The app's own list is accepted (every route's dependencies are known).
    real = create_app(settings)
    assert len(FastReads(inner, routes=real.routes, reads=FAST_READS).paths) == len(FAST_READS)


def test_steady_reads_stay_on_the_fast_path_within_the_ttl(client, headers) -> None:
    """A console polling within the caches' TTLs is answered from memory throughout; once
    they expire one request per answer goes through FastAPI (which reads again), and the
    fast path answers from the new answer after it."""
    clock = SteppedClock()
    rt = client.app.state.runtime
    clocked_caches(rt, clock, read_ttl_s=1.0, auth_ttl_s=2.0)
    layer = fast_reads_of(client.app)
    hdr = headers["viewer"]
    routes = ("/api/cells", "/api/models")
    for route in routes:  # warm: answers and sign-in cached
        assert client.get(route, headers=hdr).status_code == 200
    passed, reads, lookups = layer.passed, rt.read_cache.misses, rt.auth_cache.lookups
    for _ in range(19):  # 0.95 s of polls every 50 ms
        for route in routes:
            assert client.get(route, headers=hdr).status_code == 200
        clock.advance(0.05)
    assert layer.passed == passed and rt.read_cache.misses == reads
    clock.advance(0.1)  # the answers expire (the sign-in does not); past the TTL by a margin:
    # the clock starts at the real one's reading, so a sum landing exactly on it may round under
    for route in routes:
        assert client.get(route, headers=hdr).status_code == 200
    assert layer.passed == passed + 2 and rt.read_cache.misses == reads + 2
    answered = layer.answered
    for route in routes:
        assert client.get(route, headers=hdr).status_code == 200
    assert layer.answered == answered + 2 and rt.auth_cache.lookups == lookups
