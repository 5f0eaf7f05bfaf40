"""Bug: with every pooled database connection busy, a REST request waited SQLAlchemy's 30 s
for one and then answered 500 ``internal_error`` (the pool's ``TimeoutError`` was taken for
a bug); a database server that refused connections answered 500 too (asyncpg raised a bare
``ConnectionRefusedError``).  Both are now 503 with ``{"error", "detail"}`` and a
``Retry-After`` header, after at most ``POOL_TIMEOUT_S``."""

from __future__ import annotations

import socket
import time

from fastapi.testclient import TestClient
from sqlalchemy.engine import make_url

import backend.db.session as session_mod
from backend.app import create_app
from backend.db.session import Database


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])  # closed again when the block ends: refused


def _assert_503(r, code: str) -> None:
    assert r.status_code == 503, (r.status_code, r.text)
    body = r.json()
    assert set(body) == {"error", "detail"}, body
    assert body["error"] == code, body
    assert int(r.headers["Retry-After"]) >= 1, r.headers


def test_exhausted_pool_is_a_503_with_retry_after(settings, headers, monkeypatch):
    monkeypatch.setattr(session_mod, "POOL_SIZE", 1)
    monkeypatch.setattr(session_mod, "POOL_OVERFLOW", 0)
    monkeypatch.setattr(session_mod, "POOL_TIMEOUT_S", 0.5)
    # No read cache: the second read must reach the pool, not the answer of the first.
    settings = settings.model_copy(update={"read_cache_ttl_s": 0.0})
    with TestClient(create_app(settings)) as client:
        assert client.get("/api/models", headers=headers["viewer"]).status_code == 200
        engine = client.app.state.runtime.database.engine
        held = client.portal.call(engine.connect)  # the one connection of the pool
        try:
            t0 = time.monotonic()
            r = client.get("/api/models", headers=headers["viewer"])
            waited = time.monotonic() - t0
            _assert_503(r, "database_busy")
            assert waited < 5.0, waited  # the pool's wait, not SQLAlchemy's default 30 s
        finally:
            client.portal.call(held.close)
        # the connection back: served again
        assert client.get("/api/models", headers=headers["viewer"]).status_code == 200


def test_api_slots_all_held_is_a_503(settings, headers, monkeypatch):
    monkeypatch.setattr(session_mod, "API_SLOTS", 1)
    monkeypatch.setattr(session_mod, "POOL_TIMEOUT_S", 0.5)
    with TestClient(create_app(settings)) as client:
        db = client.app.state.runtime.database
        client.portal.call(db.api_slots.acquire)  # a request holding the only slot
        try:
            _assert_503(client.get("/api/models", headers=headers["viewer"]), "database_busy")
        finally:
            db.api_slots.release()
        assert client.get("/api/models", headers=headers["viewer"]).status_code == 200


def test_unreachable_database_is_a_503(settings, headers):
    with TestClient(create_app(settings)) as client:
        rt = client.app.state.runtime
        good = rt.database
        # the server goes away: every new connection is refused
        gone = Database(f"postgresql+asyncpg://postgres@127.0.0.1:{_closed_port()}/cell")
        rt._database = gone
        try:
            rt.auth_cache.clear()  # the sign-in itself reaches the database
            _assert_503(
                client.get("/api/models", headers=headers["viewer"]), "database_unavailable"
            )
            r = client.post(
                "/api/models", headers=headers["engineer"], json={"name": "bolt", "kind": "2d"}
            )
            _assert_503(r, "database_unavailable")
        finally:
            rt._database = good
            client.portal.call(gone.dispose)
        assert client.get("/api/models", headers=headers["viewer"]).status_code == 200


def test_locked_sqlite_file_is_a_503(tmp_path, headers, settings, monkeypatch):
    import sqlite3

    monkeypatch.setattr(settings, "database_busy_timeout_s", 0.3)
    with TestClient(create_app(settings)) as client:
        path = settings.database_url.split(":///", 1)[1]
        lock = sqlite3.connect(path, timeout=5, isolation_level=None)
        try:
            lock.execute("BEGIN EXCLUSIVE")  # another program holds the file
            client.app.state.runtime.auth_cache.clear()
            _assert_503(
                client.get("/api/models", headers=headers["viewer"]), "database_unavailable"
            )
        finally:
            lock.execute("ROLLBACK")
            lock.close()
        assert client.get("/api/models", headers=headers["viewer"]).status_code == 200


def test_postgres_cut_off_is_a_503_and_comes_back(tmp_path):
    from benchmarks.faultkit import TcpProxy
    from tests.utils.factories import make_settings, make_tokens
    from tests.utils.postgres import fresh_postgres_database

    with fresh_postgres_database("pool503") as url:
        u = make_url(url)
        proxy = TcpProxy(u.host or "127.0.0.1", u.port or 5432)
        port = proxy.start()
        try:
            via = u.set(host="127.0.0.1", port=port).render_as_string(hide_password=False)
            settings = make_settings(tmp_path, database_url=via)
            hdr = {"Authorization": f"Bearer {make_tokens(settings)['viewer']}"}
            with TestClient(create_app(settings)) as client:
                assert client.get("/api/models", headers=hdr).status_code == 200
                proxy.cut()  # the server away: open connections dropped, new ones refused
                client.app.state.runtime.auth_cache.clear()
                _assert_503(client.get("/api/models", headers=hdr), "database_unavailable")
                proxy.restore()
                assert client.get("/api/models", headers=hdr).status_code == 200
        finally:
            proxy.stop()
