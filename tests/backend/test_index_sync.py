"""The live index learns of model and view changes made by another process of the plant:
PostgreSQL LISTEN/NOTIFY, the polling fallback on the change counter (SQLite, a lost
listening connection), and local changes slipping in between a diff and its apply."""

from __future__ import annotations

import asyncio
import time

import pytest
from fastapi.testclient import TestClient
from sqlalchemy.engine import make_url

from backend.app import create_app
from backend.recognition.index import IndexedModel, LiveIndex
from tests.utils.factories import make_settings, make_tokens, migrate
from tests.utils.models import png_bytes, textured_rgb

WAIT_S = 20.0  # a bound for the waits below, never a timing assertion


def _eventually(check, *, timeout_s: float = WAIT_S, what: str = "") -> None:
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout_s:
        if check():
            return
        time.sleep(0.05)
    raise AssertionError(f"not within {timeout_s} s: {what}")


def _upload(client, hdr, model_id, seeds):
    files = [("images", (f"v{s}.png", png_bytes(textured_rgb(s)), "image/png")) for s in seeds]
    r = client.post(
        f"/api/models/{model_id}/views", files=files, data={"viewpoints": "1"}, headers=hdr
    )
    assert r.status_code == 201, r.text
    return [v["id"] for v in r.json()["data"]]


def _live(client) -> LiveIndex:
    return client.app.state.runtime.live_index


def _sync(client):
    return client.app.state.runtime.index_sync


def _follow_changes(ca, cb, hdr) -> None:
    """Every kind of change made through cell A reaches cell B's index without a restart."""
    r = ca.post("/api/models", json={"name": "gear-a", "kind": "2d", "part": "gear"}, headers=hdr)
    assert r.status_code == 201, r.text
    mid = r.json()["id"]
    _eventually(lambda: _live(cb).model(mid) is not None, what="the new model in B")
    views = _upload(ca, hdr, mid, [1, 2, 3])
    _eventually(lambda: _live(cb).views_of(mid) == sorted(views), what="the views in B")
    assert cb.get(f"/api/models/{mid}", headers=hdr).json()["indexed_views"] == 3
    with _live(cb).reading() as index:
        assert {v.model for v in index.views} == {"gear-a"}

    r = ca.patch(f"/api/models/{mid}", json={"name": "gear-b", "threshold": 0.3}, headers=hdr)
    assert r.status_code == 200, r.text
    _eventually(lambda: _live(cb).model_of_name("gear-b") is not None, what="the rename in B")
    assert _live(cb).model(mid).threshold == 0.3
    with _live(cb).reading() as index:  # the views follow the rename
        assert {v.model for v in index.views} == {"gear-b"}

    assert ca.delete(f"/api/models/{mid}/views/{views[0]}", headers=hdr).status_code == 204
    _eventually(lambda: _live(cb).views_of(mid) == sorted(views[1:]), what="view gone in B")
    # B teaches too: A learns of it (both ways).
    more = _upload(cb, hdr, mid, [4])
    _eventually(lambda: _live(ca).has_view(more[0]), what="B's view in A")
    assert ca.delete(f"/api/models/{mid}", headers=hdr).status_code == 204
    _eventually(lambda: _live(cb).model(mid) is None and len(_live(cb)) == 0, what="delete")


def test_sqlite_two_cells_follow_each_other_by_polling(tmp_path):
    url = f"sqlite+aiosqlite:///{tmp_path / 'plant.db'}"
    a = make_settings(tmp_path / "a", database_url=url, cell_name="cell-a", index_poll_s=0.1)
    b = make_settings(tmp_path / "b", database_url=url, cell_name="cell-b", index_poll_s=0.1)
    migrate(a)
    hdr = {"Authorization": f"Bearer {make_tokens(a)['engineer']}"}
    with TestClient(create_app(a)) as ca, TestClient(create_app(b)) as cb:
        assert _sync(cb).stats.mode == "poll" and not _sync(cb).listening
        _follow_changes(ca, cb, hdr)
        assert _sync(cb).stats.changes >= 4 and _sync(cb).stats.errors == 0


def test_postgres_two_cells_follow_each_other_by_notify(tmp_path, postgres_url):
    # A poll period far beyond the waits: only a notification can bring the changes in time.
    kw = {"database_url": postgres_url, "index_poll_s": 60.0}
    a = make_settings(tmp_path / "a", cell_name="cell-a", **kw)
    b = make_settings(tmp_path / "b", cell_name="cell-b", **kw)
    hdr = {"Authorization": f"Bearer {make_tokens(a)['engineer']}"}
    with TestClient(create_app(a)) as ca, TestClient(create_app(b)) as cb:
        _eventually(lambda: _sync(cb).listening, what="B listening")
        before = _sync(cb).stats.notifications
        _follow_changes(ca, cb, hdr)
        assert _sync(cb).stats.notifications > before
        assert _sync(cb).stats.mode == "listen"


def test_postgres_lost_listen_connection_polls_then_listens_again(tmp_path, postgres_url):
    kw = {"database_url": postgres_url, "index_poll_s": 0.2}
    a = make_settings(tmp_path / "a", cell_name="cell-a", **kw)
    b = make_settings(tmp_path / "b", cell_name="cell-b", **kw)
    hdr = {"Authorization": f"Bearer {make_tokens(a)['engineer']}"}
    with TestClient(create_app(a)) as ca, TestClient(create_app(b)) as cb:
        sync = _sync(cb)
        _eventually(lambda: sync.listening, what="B listening")
        assert sync.stats.reconnects == 1
        pid = sync._conn.get_server_pid()
        # Cut B's listening connection from the server side (what a restart or network does).
        _terminate(postgres_url, pid)
        _eventually(lambda: sync.stats.reconnects >= 2, what="B listening again")
        assert sync.listening and sync._conn.get_server_pid() != pid
        r = ca.post("/api/models", json={"name": "after-cut", "kind": "2d"}, headers=hdr)
        mid = r.json()["id"]
        views = _upload(ca, hdr, mid, [5, 6])
        _eventually(lambda: _live(cb).views_of(mid) == sorted(views), what="views after cut")


def _terminate(url: str, pid: int) -> None:
    import asyncpg

    async def run() -> None:
        u = make_url(url)
        conn = await asyncpg.connect(host=u.host, port=u.port, user=u.username, database="postgres")
        try:
            await conn.execute("SELECT pg_terminate_backend($1)", pid)
        finally:
            await conn.close()

    asyncio.run(run())


def test_apply_refuses_a_diff_older_than_a_local_change():
    live = LiveIndex(method="orb", max_features=200)
    m = IndexedModel(1, "m", "", "default", "2d", None)
    diff = live.diff({1: m}, {})
    assert diff.put_models == (m,) and not diff.load_views
    live.put_model(IndexedModel(1, "m2", "", "default", "2d", None))  # a local change meanwhile
    assert live.apply(diff, []) is False
    assert live.model(1).name == "m2"
    again = live.diff({1: m}, {})
    assert live.apply(again, []) is True and live.model(1).name == "m"
    assert live.diff({1: m}, {}).empty


def test_poll_period_is_bounded(tmp_path):
    from pydantic import ValidationError

    for bad in (0.0, -1.0, 61.0, float("inf"), float("nan")):
        with pytest.raises(ValidationError, match="index_poll_s"):
            make_settings(tmp_path, index_poll_s=bad)


def test_a_view_added_here_is_kept_until_its_commit_can_have_landed(monkeypatch):
    import backend.recognition.index as index_mod

    live = LiveIndex(method="orb", max_features=200)
    m = IndexedModel(1, "m", "m", "default", "2d", None)
    live.add_view(m, 7, 1, live.extract(textured_rgb(3), None))
    # A snapshot taken before this process's transaction committed lacks view 7: kept.
    diff = live.diff({1: m}, {})
    assert diff.remove_views == () and diff.deferred
    assert live.apply(diff, []) and live.has_view(7)
    monkeypatch.setattr(index_mod, "LOCAL_GRACE_S", 0.0)  # long after: it really is gone
    diff = live.diff({1: m}, {})
    assert diff.remove_views == (7,) and not diff.deferred
    assert live.apply(diff, []) and not live.has_view(7)
