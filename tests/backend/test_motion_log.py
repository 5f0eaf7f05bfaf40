"""The motion audit log (``backend.cell.motionlog``): every motion the cell commands is one
line written before the driver gets it, with the state that allowed it, and one after;
a line torn by a crash is skipped when reading."""

from __future__ import annotations

import json

import numpy as np
from fastapi.testclient import TestClient

from backend.app import create_app
from backend.cell.motionlog import MotionLog, read_motion_log
from robot.model import ASEA
from tests.utils.factories import make_settings, make_tokens, migrate


def test_each_move_is_logged_with_its_lock_state_and_end(tmp_path):
    path = tmp_path / "audit" / "motion.jsonl"
    settings = make_settings(tmp_path, motion_log=path)
    migrate(settings)
    hdr = {"Authorization": f"Bearer {make_tokens(settings)['operator']}"}
    ready = [float(v) for v in ASEA.q_ready]
    with TestClient(create_app(settings)) as client:
        r = client.post("/api/robot/move?wait=true", json={"joints": ready}, headers=hdr)
        assert r.status_code == 200, r.text
        r = client.post("/api/robot/move", json={"joints": [9.0, 0, 0, 0, 0]}, headers=hdr)
        assert r.status_code == 422  # refused before the driver: not a commanded motion
    moves = read_motion_log(path)
    assert len(moves) == 1, moves
    m = moves[0]
    assert m["within_limits"] and m["connected"] and not m["estopped"], m
    assert m["lock"], m  # the motion job held the arm
    assert np.allclose(m["goal"], ready, atol=1e-6)
    assert m["end"]["completed"] is True and np.allclose(m["end"]["q"], ready, atol=1e-3)


def test_torn_lines_and_moves_without_end_are_read(tmp_path):
    path = tmp_path / "m.jsonl"
    log = MotionLog(path)
    log.write({"ev": "move", "t": 1.0, "pid": 7, "seq": 1, "goal": [0.0] * 5})
    log.write({"ev": "end", "t": 2.0, "pid": 7, "seq": 1, "completed": True})
    log.write({"ev": "move", "t": 3.0, "pid": 7, "seq": 2, "goal": [0.0] * 5})
    log.close()
    with path.open("a") as f:
        f.write('{"ev": "end", "pid": 7, "se')  # the writer killed mid-line
    moves = read_motion_log(path)
    assert [m["seq"] for m in moves] == [1, 2]
    assert moves[0]["end"]["completed"] is True and moves[1]["end"] is None
    assert json.loads(path.read_text().splitlines()[0])["pid"] == 7


def test_two_drivers_of_one_process_share_a_file_without_mixing(tmp_path):
    """Bug found by the fault campaign: a runtime started again in the same process counted
    its moves from 1 again and the reader merged them with the first runtime's (11 teach
    moves vanished from the audit)."""
    import asyncio

    from backend.cell.motionlog import LoggedDriver
    from robot.drivers.ideal import IdealDriver
    from robot.trajectory import plan_joint_move

    path = tmp_path / "m.jsonl"

    async def one_runtime() -> None:
        inner = IdealDriver(time_scale=50.0)
        await inner.connect()
        log = MotionLog(path)
        drv = LoggedDriver(inner, log, holder=lambda: "test")
        q0 = np.asarray(inner.state.q)
        await drv.move(plan_joint_move(q0, ASEA.q_ready, speed=1.0))
        await inner.close()
        log.close()

    asyncio.run(one_runtime())
    asyncio.run(one_runtime())
    moves = read_motion_log(path)
    assert len(moves) == 2 and all(m["end"] is not None for m in moves), moves
