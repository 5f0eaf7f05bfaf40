"""Waiting for a part: the tracker of an indexing run, the operator's messages, and a run
that goes on when looking for a part fails (the cell holds, then looks again)."""

from __future__ import annotations

import asyncio
import math
from types import SimpleNamespace

import numpy as np
import pytest

from backend.cell.events import CameraStatus
from backend.inspection import runner, service, waiting
from backend.inspection.errors import NotReady
from backend.inspection.state import InspectionState
from backend.jobs import JobManager
from backend.recognition.segment import SegmentationFailed, foreground_mask
from robot.drivers.conveyor import BeltStatus, FixedStation
from vision.errors import CameraError


def test_the_tracker_tells_the_next_part_by_its_belt_coordinate_and_region():
    t = waiting.PartTracker()
    here = np.zeros((40, 60), bool)
    here[10:30, 20:40] = True
    assert t.is_new(0.3, here)  # nothing inspected yet
    t.inspected(0.3, here)
    assert not t.is_new(0.3 + 0.01, here)  # the same part, still at the station
    assert t.is_new(0.3 - 0.42, here)  # the next one, 0.42 m upstream
    assert t.is_new(0.3 - 2.6, here)  # the same part a loop later: new
    other = np.zeros_like(here)
    other[5:35, 15:28] = True  # put by hand where the last one stood: another region
    assert t.is_new(0.3, other)
    t.station_empty()
    assert t.is_new(0.3, here)  # the station was seen empty
    t.inspected(math.nan, here)  # nothing measured: nothing noted
    assert t.last_u is None and t.last_mask is None


@pytest.mark.parametrize(
    ("status", "says"),
    [
        (None, "no belt the cell can read"),
        (BeltStatus(False, False, "index", 0.1, False, 0.0, 0), "belt stopped, 0 object(s) on it: put a part on it"),
        (BeltStatus(False, False, "index", 0.1, False, 0.0, 3), "belt stopped, 3 object(s) on it: start the belt"),
        (BeltStatus(False, True, "index", 0.1, False, 0.0, 3), "halted by the emergency stop"),
        (BeltStatus(True, False, "index", 0.08, False, 0.0, None), "belt running (index, 0.08 m/s)"),
    ],
)  # fmt: skip
def test_the_waiting_message_names_the_belt(status, says):
    msg = waiting.waiting_message(status)
    assert msg.startswith("waiting for a part at the station: ") and says in msg, msg
    assert waiting.waiting_message(status, same_part=True).startswith("waiting for the next part")


def test_the_blob_nearest_the_station_is_the_part_not_a_larger_neighbour():
    bg = np.full((120, 200, 3), 60, np.uint8)
    img = bg.copy()
    img[10:110, 0:40] = 200  # a neighbour cut by the image's edge: larger
    img[45:75, 85:115] = 200  # the part at the station (the image's centre)
    assert foreground_mask(img, bg)[:, :40].any()  # the largest blob by default
    near = foreground_mask(img, bg, near_px=(100, 60))
    assert near[60, 100] and not near[:, :40].any()
    img[58:62, 150:154] = 200  # a speck nearer than nothing, smaller than a tenth: ignored
    assert foreground_mask(img, bg, near_px=(152, 60))[60, 100]
    with pytest.raises(ValueError, match="near_px"):
        foreground_mask(img, bg, near_px=(float("nan"), 1))
    with pytest.raises(SegmentationFailed):
        foreground_mask(bg, bg, near_px=(100, 60))


class _Cell:
    conveyors = ()

    def check_can_move(self) -> None:
        pass

    def camera_status(self) -> CameraStatus:
        return CameraStatus(name="cam", ok=True, frames=1, fps=1.0, error="", retries=0)

    @property
    def state(self):
        return SimpleNamespace(connected=True, fault="")


class _Db:
    async def ping(self) -> bool:
        return True


async def test_a_run_looks_again_when_looking_for_a_part_fails_and_ends_when_setup_is_missing(
    monkeypatch,
):
    rt = SimpleNamespace(cell=_Cell(), jobs=JobManager(), live_index=[1],
                         conveyor=FixedStation(), database=_Db(),
                         inspection=InspectionState())  # fmt: skip
    outcomes = iter([CameraError("camera stalled"), "unknown", "recognized"])

    async def fake_context(rt):
        return SimpleNamespace()

    async def fake_inspect(ctx, opts, job=None, *, tracker=None, waiting=None, db_wait_s=None,
                           resolve=None):  # fmt: skip
        out = next(outcomes)
        if isinstance(out, Exception):
            raise out
        return {"id": 1, "decision": out, "model": None}

    monkeypatch.setattr(runner, "context", fake_context)
    monkeypatch.setattr(runner, "inspect_object", fake_inspect)
    messages: list[str] = []
    run = service.start_run(rt, service.InspectOptions(), 2)
    run.job.on_report = lambda j: messages.append(j.message)
    await asyncio.wait_for(rt.jobs.wait(run.job), 120)
    assert run.job.state.value == "done", run.job.error
    assert run.job.result["inspected"] == 2
    assert any("looking for a part failed (camera_error" in m for m in messages), messages

    async def not_ready(*a, **k):
        raise NotReady("no trained views: teach a model first")

    monkeypatch.setattr(runner, "inspect_object", not_ready)
    run = service.start_run(rt, service.InspectOptions(), None)
    await asyncio.wait_for(rt.jobs.wait(run.job), 120)
    assert run.job.state.value == "failed" and "teach a model" in run.job.error["detail"]
