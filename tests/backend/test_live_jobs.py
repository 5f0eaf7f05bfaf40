"""The WebSocket carries jobs from the event bus: start, throttled progress, end."""

from __future__ import annotations

import asyncio

from backend.api.deps import runtime_of


def _jobs_until_done(ws, job_id, limit=500):
    seen = []
    for _ in range(limit):
        msg = ws.receive_json()
        if msg["type"] == "job" and msg["job"]["id"] == job_id:
            seen.append(msg["job"])
            if msg["job"]["state"] != "running":
                return seen
    raise AssertionError(f"job {job_id} did not end within {limit} messages")


def test_job_progress_reaches_the_websocket_throttled(client, tokens):
    app = client.app
    cell = runtime_of(app).cell

    async def body(job):
        for k in range(1, 51):  # 50 reports within about 1 s
            job.report(k / 50, f"step {k}")
            await asyncio.sleep(0.02)
        return {"steps": 50}

    with client.websocket_connect("/api/ws") as ws:
        ws.send_json({"token": tokens["viewer"]})
        assert ws.receive_json()["type"] == "hello"
        job = client.portal.call(lambda: _start(cell, body))
        seen = _jobs_until_done(ws, job.id)
    assert seen[0]["state"] == "running"
    progress = [j for j in seen[1:-1] if j["state"] == "running"]
    # Some progress arrives, at most about 4 per second (1 s of reports + the trailing one).
    assert 2 <= len(progress) <= 8, [p["message"] for p in progress]
    fractions = [p["progress"] for p in progress]
    assert fractions == sorted(fractions) and 0 < fractions[0] < 1
    assert seen[-1]["state"] == "done" and seen[-1]["result"] == {"steps": 50}


async def _start(cell, body):
    return cell.jobs.start("count", body)


def test_move_jobs_reach_the_websocket(client, tokens, headers):
    with client.websocket_connect("/api/ws") as ws:
        ws.send_json({"token": tokens["viewer"]})
        assert ws.receive_json()["type"] == "hello"
        r = client.post("/api/robot/home", json={"speed": 1.0}, headers=headers["operator"])
        assert r.status_code == 202
        seen = _jobs_until_done(ws, r.json()["job"]["id"])
    assert seen[0]["kind"] == "home" and seen[-1]["state"] == "done"
    assert seen[-1]["result"]["completed"] is True
