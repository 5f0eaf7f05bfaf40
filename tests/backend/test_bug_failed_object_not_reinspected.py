"""Bug (fault campaign): in index mode a continuous run waited, before every object but the
first, for the station to empty.  After a ``failed`` inspection (camera stall, link drop)
the object is still there, so the run waited ``wait_s``, stored a second failure and the
object was never inspected.  Now the run looks at the station again after a failure (the
belt keeps the part there: it is released only after a complete inspection), and holds (no
motion) while the camera or the arm's link is down or the database is away."""

from __future__ import annotations

import asyncio
from types import SimpleNamespace

from backend.cell.events import CameraStatus
from backend.inspection import runner, service
from backend.inspection.state import InspectionState
from backend.jobs import JobManager
from robot.drivers.conveyor import BeltStatus


class _Conveyor:
    """An indexing belt that records what the run asks of it."""

    name = "belt"
    halted = False
    controllable = True

    def __init__(self) -> None:
        self.calls: list[str] = []

    def status(self) -> BeltStatus:
        return BeltStatus(True, False, "index", 0.1, True, 0.0, None)

    async def halt(self) -> None: ...

    async def resume(self) -> None: ...

    async def set_running(self, running: bool) -> BeltStatus:
        return self.status()

    async def release(self) -> None:
        self.calls.append("release")

    async def hold_at_station(self, hold: bool) -> None:
        self.calls.append(f"hold {hold}")


class _Cell:
    def __init__(self) -> None:
        self.camera_ok = True
        self.connected = True
        self.conveyors = [_Conveyor()]

    def check_can_move(self) -> None:
        pass

    def camera_status(self) -> CameraStatus:
        return CameraStatus(name="cam", ok=self.camera_ok, frames=1, fps=1.0,
                            error="" if self.camera_ok else "camera stalled", retries=0)  # fmt: skip

    @property
    def state(self):
        return SimpleNamespace(connected=self.connected, fault="")


class _Db:
    def __init__(self) -> None:
        self.down = 0

    async def ping(self) -> bool:
        if self.down:
            self.down -= 1
            return False
        return True


async def test_the_run_looks_again_after_a_failure_and_holds_while_not_ready(monkeypatch):
    cell, db = _Cell(), _Db()
    rt = SimpleNamespace(cell=cell, jobs=JobManager(), live_index=[1],
                         conveyor=cell.conveyors[0], database=db,
                         inspection=InspectionState())  # fmt: skip
    seen: list[tuple[bool, bool]] = []
    decisions = iter(["unknown", "failed", "unknown", "failed", "recognized"])

    async def fake_context(rt):
        return SimpleNamespace()

    async def fake_inspect(ctx, opts, job=None, *, tracker=None, waiting=None, db_wait_s=None,
                           resolve=None):  # fmt: skip
        belt = cell.conveyors[0]
        seen.append((belt.calls.count("release"), cell.camera_ok))
        assert tracker is not None and waiting.forever  # a run waits for parts until stopped
        d = next(decisions)
        if d == "failed":  # the fault: the camera fails, the database goes for 2 checks
            cell.camera_ok = False
            db.down = 2
            asyncio.get_running_loop().call_later(0.3, setattr, cell, "camera_ok", True)
        return {"id": len(seen), "decision": d, "model": None}

    monkeypatch.setattr(runner, "context", fake_context)
    monkeypatch.setattr(runner, "inspect_object", fake_inspect)
    messages: list[str] = []
    run = service.start_run(rt, service.InspectOptions(), 5)
    run.job.on_report = lambda j: messages.append(j.message)
    await rt.jobs.wait(run.job)
    assert run.job.state.value == "done", run.job.error
    # the run holds each part at the station; after a complete inspection the belt brings
    # the next one, after a failed one the run looks at the same part again
    assert [c for c, _ in seen] == [0, 1, 1, 2, 2]
    assert cell.conveyors[0].calls == ["hold True", "release", "release", "release", "hold False"]
    assert all(ok for _, ok in seen)  # never started while the camera was failing
    assert any("holding: camera cam: camera stalled" in m for m in messages)
    assert any("database unavailable" in m for m in messages)
