"""Cell-wide E-STOP: the conveyor stops with the arm, refuses to start, and resumes only on
reset (simulated belt through the API; any conveyor driver through the protocol)."""

from __future__ import annotations

import time

import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from backend.cell import CellStopped
from robot.drivers.conveyor import ConveyorDriver
from tests.utils.cells import ideal_cell
from tests.utils.factories import make_settings, make_tokens, migrate

pytestmark = pytest.mark.slow


def _travel(c, hdr) -> dict:
    r = c.get("/api/sim/conveyor", headers=hdr)
    assert r.status_code == 200, r.text
    return r.json()["conveyor"]


def test_estop_stops_the_simulated_conveyor_until_reset(tmp_path):
    s = make_settings(tmp_path, driver="sim", camera="sim", sim_demo=False, camera_idle_fps=0.5)
    migrate(s)
    tokens = make_tokens(s)
    eng = {"Authorization": f"Bearer {tokens['engineer']}"}
    viewer = {"Authorization": f"Bearer {tokens['viewer']}"}
    with TestClient(create_app(s)) as c:
        r = c.post("/api/sim/conveyor", json={"running": True, "speed_m_s": 0.2,
                   "mode": "continuous"}, headers=eng)  # fmt: skip
        assert r.status_code == 200, r.text
        t0 = _travel(c, eng)["travel_m"]
        time.sleep(0.3)
        assert _travel(c, eng)["travel_m"] > t0  # the belt runs

        assert c.post("/api/robot/estop", headers=viewer).status_code == 200
        halted = _travel(c, eng)
        assert halted["halted"] is True and halted["running"] is False
        time.sleep(0.3)
        assert _travel(c, eng)["travel_m"] == halted["travel_m"]  # stands still
        r = c.post("/api/sim/conveyor", json={"running": True}, headers=eng)
        assert r.status_code == 409 and "emergency stop" in r.json()["detail"]
        assert c.get("/api/status", headers=eng).json()["cell"]["estopped"] is True
        time.sleep(0.2)
        assert _travel(c, eng)["travel_m"] == halted["travel_m"]

        assert c.post("/api/robot/reset", headers=eng).status_code == 200
        back = _travel(c, eng)
        assert back["halted"] is False and back["running"] is True  # it was running: resumes
        time.sleep(0.3)
        assert _travel(c, eng)["travel_m"] > back["travel_m"]
        assert c.get("/api/status", headers=eng).json()["cell"]["estopped"] is False


class _Belt:
    def __init__(self, name: str, *, broken: bool = False) -> None:
        self.name = name
        self.broken = broken
        self.halted = False
        self.calls: list[str] = []

    async def halt(self) -> None:
        self.calls.append("halt")
        if self.broken:
            raise OSError("PLC does not answer")
        self.halted = True

    async def resume(self) -> None:
        self.calls.append("resume")
        self.halted = False


@pytest.mark.parametrize("broken_first", [True, False])
async def test_estop_halts_every_conveyor_driver(settings, broken_first):
    a, b = _Belt("a", broken=broken_first), _Belt("b")
    assert isinstance(a, ConveyorDriver)
    cell, driver, _ = ideal_cell(settings, conveyors=[a, b])
    events = []
    cell.bus.add_listener(events.append, CellStopped)
    await cell.start()
    try:
        await cell.estop()
        assert driver.state.estopped and b.halted and a.calls == ["halt"]
        assert cell.estopped
        assert events[-1].active and "b" in events[-1].conveyors
        await cell.reset()
        assert not b.halted and b.calls == ["halt", "resume"] and not driver.state.estopped
        assert events[-1] == CellStopped(
            active=False, conveyors=("a", "b"), stamp_s=events[-1].stamp_s
        )
    finally:
        await cell.stop()
