"""Bug: under a surge of REST readers (``benchmarks/load.py``: 50 clients on a starved
machine) the requests held all 15 pooled database connections and the inspection in
progress waited for one until it timed out.  REST requests now hold at most
``API_SLOTS`` connections at once; the rest of the pool stays for the cell."""

from __future__ import annotations

import concurrent.futures
import threading

from fastapi.testclient import TestClient
from sqlalchemy import event

import backend.db.session as session_mod
from backend.app import create_app
from backend.caches import AuthCache


def test_readers_hold_at_most_their_slots(settings, headers, monkeypatch):
    monkeypatch.setattr(session_mod, "API_SLOTS", 2)
    with TestClient(create_app(settings)) as client:
        rt = client.app.state.runtime
        rt.auth_cache = AuthCache(ttl_s=0.0)  # every request signs in through the database too
        pool = rt.database.engine.sync_engine.pool
        lock, now, peak = threading.Lock(), [0], [0]

        def out(*_a):
            with lock:
                now[0] += 1
                peak[0] = max(peak[0], now[0])

        def back(*_a):
            with lock:
                now[0] -= 1

        event.listen(pool, "checkout", out)
        event.listen(pool, "checkin", back)

        def read(_k: int) -> int:
            return client.get("/api/models", headers=headers["viewer"]).status_code

        with concurrent.futures.ThreadPoolExecutor(max_workers=8) as ex:
            codes = list(ex.map(read, range(40)))
        assert set(codes) == {200}
        # Two for the readers, and room for the cell's own tasks (index sync, jobs).
        assert peak[0] <= 2 + 2, peak[0]
        assert rt.database.api_slots._value == 2  # every slot given back
