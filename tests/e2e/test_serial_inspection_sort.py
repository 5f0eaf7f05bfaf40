"""Teach, inspect and sort through the serial controller: REST -> SerialDriver -> PTY ->
emulator -> the simulated arm and suction cup (issue 14, "Done when").

The emulator runs on its own thread and event loop, backed by the simulator's driver
(``SimDriver``) of the same simulated cell whose camera the backend uses, so the
``GRIP`` command really works the suction cup: it seals on the part under it, carries its
mass, releases it over the bin; the simulator's truth says where each part landed.
"""

from __future__ import annotations

import asyncio
import functools
import threading
import time

import pytest
from fastapi.testclient import TestClient

import robot.drivers.serial
from backend import hardware
from backend.app import create_app
from robot.drivers.serial.emulator import Emulator
from robot.sim import CATALOGUE, SimConfig, SimDriver, SimEngine, suction_point
from tests.utils.cli import wait_station_seen_empty
from tests.utils.factories import make_settings, make_tokens, migrate


def _wait(client, headers, job_id, *, until=None, timeout_s=400.0):
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout_s:
        job = client.get(f"/api/jobs/{job_id}", headers=headers).json()["job"]
        if job["state"] != "running" or (until is not None and until in job["message"]):
            return job
        time.sleep(0.2)
    raise AssertionError(f"job {job_id} still running after {timeout_s} s: {job['message']}")


@pytest.fixture
def serial_sim(tmp_path, monkeypatch):
    """One simulated cell; the emulated controller on a PTY drives its arm and gripper."""
    hardware.headless_mujoco()
    engine = SimEngine(SimConfig(state_rate_hz=50.0), time_scale=5.0)
    link = str(tmp_path / "robot-tty")
    ready = threading.Event()
    loop = asyncio.new_event_loop()
    box: dict = {}

    async def serve() -> None:
        box["stop"] = asyncio.Event()
        driver = SimDriver(engine)
        await driver.connect()
        box["emu"] = emu = Emulator(driver, link=link, watchdog_s=10.0)
        try:
            await emu.start()
            ready.set()
            await box["stop"].wait()
        finally:
            await emu.close()
            await driver.close()

    def run() -> None:
        box["task"] = loop.create_task(serve())
        loop.run_until_complete(box["task"])

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    assert ready.wait(20), "emulator did not start"
    # The backend's simulated camera renders this same cell (following the serial arm).
    monkeypatch.setattr(hardware, "make_sim_engine", lambda settings: engine)
    # One process plays the controller, the arm's physics, the renderer and the backend on
    # a shared machine: allow the controller longer silences than a real line would.
    monkeypatch.setattr(
        robot.drivers.serial, "SerialDriver",
        functools.partial(robot.drivers.serial.SerialDriver, silence_timeout_s=10.0,
                          command_timeout_s=10.0, connect_timeout_s=10.0),
    )  # fmt: skip
    yield engine, link, box
    loop.call_soon_threadsafe(box["stop"].set)
    thread.join(20)


@pytest.mark.timeout(2400)  # teaching and three picks through the serial link, simulated
def test_teach_inspect_and_sort_over_the_serial_link(tmp_path, serial_sim):
    engine, link, box = serial_sim
    settings = make_settings(tmp_path, driver="serial", serial_port=link, camera="sim",
                             sim_demo=False, time_scale=5.0)  # fmt: skip
    migrate(settings)
    tokens = make_tokens(settings)
    h = {r: {"Authorization": f"Bearer {t}"} for r, t in tokens.items()}
    eng, op = h["engineer"], h["operator"]
    spec = engine.config.layout.conveyor
    station = spec.station_s_m
    with TestClient(create_app(settings)) as client:
        status = client.get("/api/status", headers=op).json()
        assert status["driver"]["name"] == "serial" and status["driver"]["connected"] is True
        engine.clear_objects()
        engine.configure_conveyor(running=False, mode="index", dwell_s=None)
        # Two models through the API; height and grasp point entered from the drawings.
        ids = {}
        for name, kind in (("gear-housing", "3d"), ("wheel-steel", "2d")):
            body = {"name": name, "kind": kind, "part": CATALOGUE[name].base_of,
                    "height_m": float(CATALOGUE[name].geometry().bounds[1, 2]),
                    "grasp_obj": [float(v) for v in suction_point(name)]}  # fmt: skip
            r = client.post("/api/models", json=body, headers=eng)
            assert r.status_code == 201, r.text
            assert r.json()["geometry_source"] == "entered"
            assert r.json()["grasp_obj"] == pytest.approx(body["grasp_obj"])
            ids[name] = r.json()["id"]
        r = client.post(f"/api/models/{ids['gear-housing']}/teach",
                        json={"background": "grab", "wait_s": 60}, headers=eng)  # fmt: skip
        job = _wait(client, eng, r.json()["job"]["id"], until="waiting for an object")
        engine.spawn("gear-housing", s_m=station, yaw_rad=0.0)
        job = _wait(client, eng, job["id"])
        assert job["state"] == "done", job
        engine.clear_objects()
        engine.spawn("wheel-steel", s_m=station, yaw_rad=0.0)
        r = client.post(f"/api/models/{ids['wheel-steel']}/teach", json={"background": "stored"},
                        headers=eng)  # fmt: skip
        job = _wait(client, eng, r.json()["job"]["id"])
        assert job["state"] == "done", job
        engine.clear_objects()

        # A short continuous run with sorting: two trained parts and an untrained one.
        placed = [("gear-housing", 0.1), ("oil-filter", 0.4), ("wheel-steel", -1.0)]
        r = client.post("/api/inspection/run",
                        json={"policy": "two-views", "count": 3, "wait_s": 120, "sort": True},
                        headers=op)  # fmt: skip
        assert r.status_code == 202, r.text
        run_id = r.json()["job"]["id"]
        for k, (name, yaw) in enumerate(placed):
            engine.spawn(name, s_m=station + 0.002, lateral_m=-0.002, yaw_rad=yaw)
            t0 = time.monotonic()
            while client.get("/api/inspections", headers=op).json()["count"] < k + 1:
                assert time.monotonic() - t0 < 600, f"no inspection of {name}"
                time.sleep(0.3)
            engine.clear_objects()  # anything the pick left behind
            # the run sees the station empty before the next object comes
            wait_station_seen_empty(client, op, run_id, done=k + 1, count=len(placed))
        job = _wait(client, op, run_id)
        assert job["state"] == "done", job
        rows = sorted(client.get("/api/inspections?limit=10", headers=op).json()["data"],
                      key=lambda d: d["id"])  # fmt: skip
        assert len(rows) == 3
        bins = engine.bins()
        landed = {ld.name: ld.place for ld in engine.landings()}
        seen = [((r["truth"] or {}).get("name"), r["decision"], r["reason"][:90], r["pick"])
                for r in rows]  # fmt: skip
        for row, (name, _yaw) in zip(rows, placed, strict=True):
            assert row["truth"] is not None and row["truth"]["name"] == name, seen
            want = "unknown" if name == "oil-filter" else "recognized"
            assert row["decision"] == want, (name, row["decision"], row["reason"])
            if want == "recognized":
                assert row["model"] == name
            pick = row["pick"]
            assert pick["sorted"] is True and pick["ok"] is True, (name, pick)
            target = next(
                b.name for b in engine.config.layout.bins
                if (b.reject if want == "unknown" else CATALOGUE[name].base_of in b.parts)
            )  # fmt: skip
            assert pick["bin"] == target and landed[name] == target, (name, pick, landed)
            assert any(i for i in bins[target]), bins
        # The emulator's own count of GRIP commands: it switched the cup on and off for each
        # pick; the two model picks sealed at their GRIP 1 (the cup set down on the grasp
        # point), the unknown one during the guarded descent after it (its landing in the
        # reject bin, checked above, is that seal).
        stats = box["emu"].stats
        assert stats.grips_holding >= 2 and stats.grips >= 6 and stats.grips_refused == 0
