"""The short version of the load campaign (``benchmarks/load.py``): a few REST clients and
console WebSockets against a running ``visioncell serve`` while the arm moves; behaviour
only (every read answered, every message timed), no timing assertions."""

from __future__ import annotations

import asyncio
import math

import httpx
import pytest

from benchmarks.load import ROUTES, run_clients
from robot.model import ASEA
from tests.e2e.conftest import start_server


@pytest.fixture
def server(tmp_path):
    s = start_server(tmp_path, VISIONCELL_VIEW3D_ENABLED="false")
    yield s
    s.stop()


def test_a_few_clients_and_sockets_while_the_arm_moves(server):
    token = server.token("load-operator", "operator")
    hdr = {"Authorization": f"Bearer {token}"}

    async def run() -> dict:
        stop = asyncio.Event()
        clients = asyncio.create_task(
            run_clients(server.base, token, clients=3, sockets=2, think_s=0.05, stop=stop)
        )
        async with httpx.AsyncClient(base_url=server.base, headers=hdr, timeout=30) as c:
            await asyncio.sleep(0.5)
            for q in (ASEA.q_ready, ASEA.q_ready * 0.9, ASEA.q_ready):
                r = await c.post("/api/robot/move?wait=true",
                                 json={"joints": [float(v) for v in q], "speed": 1.0})  # fmt: skip
                assert r.status_code == 200, r.text
        await asyncio.sleep(0.5)
        stop.set()
        return await asyncio.wait_for(clients, 60)

    res = asyncio.run(run())
    assert set(res["routes"]) == {r.split("?")[0] for r in ROUTES}
    for name, r in res["routes"].items():
        assert r["n"] >= 1, (name, r)
        assert set(r["status"]) == {"200"}, (name, r["status"])
        assert 0 < r["p50_ms"] <= r["p99_ms"] <= r["max_ms"]
    assert res["ok"] == res["requests"] > 0
    assert not res["ws_errors"], res["ws_errors"]
    # Both sockets saw the arm's state and the move jobs, every message with its event time.
    assert res["ws_kinds"].get("state", 0) >= 2 and res["ws_kinds"].get("job", 0) >= 2
    assert res["ws_messages"] == sum(v for k, v in res["ws_kinds"].items() if k != "hello")
    assert math.isfinite(res["ws_lag_p99_ms"]) and res["ws_lag_p50_ms"] >= 0.0


def test_client_counts_are_bounded():
    stop = asyncio.Event()
    for kw in ({"clients": 501, "sockets": 0}, {"clients": 0, "sockets": 101}):
        with pytest.raises(ValueError):
            asyncio.run(run_clients("http://127.0.0.1:1", "t", think_s=0.0, stop=stop, **kw))
    with pytest.raises(ValueError, match="think_s"):
        asyncio.run(run_clients("http://127.0.0.1:1", "t", clients=1, sockets=0,
                                think_s=float("nan"), stop=stop))  # fmt: skip
