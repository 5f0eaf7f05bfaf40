"""E-STOP during a database outage: the answer comes at once, the arm and the conveyors are
latched and the cell-wide ``estop`` event goes out, whether the database refuses sessions
or hangs on them; the E-STOP's audit record is written once the database is back."""

from __future__ import annotations

import time
from collections.abc import Callable

import pytest
from fastapi.testclient import TestClient

from backend.api.deps import runtime_of
from backend.app import create_app
from backend.cell import CellStopped
from benchmarks.outage import DatabaseOutage
from robot.model import ASEA
from tests.utils.factories import make_settings, make_tokens, migrate
from tests.utils.serial import emulated_controller

#: Bounds a hang only: what is waited for normally happens within a second.
HANG_S = 120.0


class Belt:
    """A conveyor driver that records its halt."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.halted = False

    async def halt(self) -> None:
        self.halted = True

    async def resume(self) -> None:
        self.halted = False


def until(pred: Callable[[], bool], what: str) -> None:
    t0 = time.monotonic()
    while not pred():
        assert time.monotonic() - t0 < HANG_S, f"still waiting for {what}"
        time.sleep(0.02)


@pytest.mark.parametrize("mode", ["block", "fail"])
def test_estop_latches_and_answers_while_the_database_is_away(settings, headers, mode):
    with TestClient(create_app(settings)) as c:
        rt = runtime_of(c.app)
        belt = Belt("belt-a")
        rt.cell.conveyors.append(belt)
        events: list[CellStopped] = []
        rt.bus.add_listener(events.append, CellStopped)
        rt.auth_cache.clear()  # the token is known from memory only, not from the 2 s cache
        with DatabaseOutage(rt.database, mode=mode) as outage:
            r = c.post("/api/robot/estop", headers=headers["viewer"])
            assert r.status_code == 200, r.text
            assert r.json()["state"]["estopped"] is True
            assert rt.cell.driver.state.estopped and belt.halted and rt.cell.estopped
            assert len(events) == 1
            e = events[0]
            assert (e.active, e.conveyors, e.by, e.role, e.source, e.arm_latched) == (
                True, ("belt-a",), "test-viewer", "viewer", "rest", True,
            )  # fmt: skip
            # the record waits for the database
            until(lambda: outage.hit >= 1, "the audit writer to try")
            assert rt.estop_log.written == 0 and rt.estop_log.pending == 1
        until(lambda: rt.estop_log.written == 1, "the audit record")
        r = c.get("/api/audit", params={"kind": "estop"}, headers=headers["engineer"])
        assert r.status_code == 200, r.text
        (row,) = r.json()["data"]
        assert (row["actor"], row["actor_role"], row["action"], row["entity_id"]) == (
            "test-viewer", "viewer", "press", settings.cell_name,
        )  # fmt: skip
        assert row["new"]["source"] == "rest" and row["new"]["conveyors"] == ["belt-a"]
        assert row["new"]["arm_latched"] is True
        # a reset is recorded too
        assert c.post("/api/robot/reset", headers=headers["operator"]).status_code == 200
        until(lambda: rt.estop_log.written == 2, "the reset's record")
        assert not belt.halted


def test_an_unwritten_record_is_logged_when_the_cell_stops(settings, headers, caplog):
    with TestClient(create_app(settings)) as c:
        rt = runtime_of(c.app)
        outage = DatabaseOutage(rt.database, mode="fail")
        outage.start()
        assert c.post("/api/robot/estop", headers=headers["viewer"]).status_code == 200
        until(lambda: outage.hit >= 1, "the audit writer to try")
    outage.end()
    lost = [r for r in caplog.records if "audit record NOT written" in r.getMessage()]
    assert len(lost) == 1 and "E-STOP by test-viewer (viewer) via rest" in lost[0].getMessage()


def test_estop_of_a_serial_controller_while_the_database_hangs(tmp_path):
    """The serial controller's path: the ESTOP line goes out and is acknowledged, the move
    in progress is cancelled, while every database session hangs."""
    with emulated_controller(tmp_path, time_scale=1.0) as port:
        s = make_settings(tmp_path, driver="serial", serial_port=port)
        migrate(s)
        tokens = make_tokens(s)
        with TestClient(create_app(s)) as c:
            rt = runtime_of(c.app)
            op = {"Authorization": f"Bearer {tokens['operator']}"}
            ready = [float(v) for v in ASEA.q_ready]
            # The link comes up on its own after the start and may drop on a loaded machine
            # (the controller's watchdog); a move sent while it is down fails at once with
            # the link named, and is sent again once the link is back.
            for _ in range(3):
                until(lambda: rt.cell.driver.state.connected, "the controller's link")
                r = c.post("/api/robot/move", json={"joints": ready, "speed": 0.05}, headers=op)
                assert r.status_code == 202, r.text
                job_id = r.json()["job"]["id"]
                job = rt.cell.jobs.get(job_id)
                until(lambda j=job: rt.cell.driver.state.moving or j.state.value != "running",
                      "the move to start")  # fmt: skip
                if job.state.value == "running" or "connected" not in str(job.error):
                    break
            assert job.state.value == "running", (job.state, job.message, job.error)
            with DatabaseOutage(rt.database, mode="block"):
                r = c.post(
                    "/api/robot/estop", headers={"Authorization": f"Bearer {tokens['viewer']}"}
                )
                assert r.status_code == 200, r.text
                assert r.json()["state"]["estopped"] is True
                until(lambda: rt.cell.jobs.get(job_id).state.value != "running", "the move's end")
                assert rt.cell.jobs.get(job_id).state.value in ("cancelled", "failed")
            # latched: the controller refuses to move until a reset
            r = c.post("/api/robot/move", json={"joints": ready}, headers=op)
            assert r.status_code == 409, r.text
            assert rt.cell.driver.state.estopped
