"""The inspection's pipeline parts on their own: the stopwatch on an injected clock, the
stored result answered without reading it back, the live messages by event type, and one
set of option rules for inspections and recipes."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from backend.api.routes.live import MESSAGES, _body
from backend.cell import EventBus
from backend.cell.events import CellEvent, InspectionDone
from backend.db.session import Database
from backend.db.types import utcnow
from backend.inspection import record, results
from backend.inspection.draft import InspectionDraft
from backend.inspection.options import InspectOptions
from backend.inspection.stopwatch import Stopwatch
from backend.recipes.model import RecipeOptions
from backend.runtime import ensure_cell_row
from tests.utils.factories import make_settings, migrate
from vision.errors import InvalidInput


class _Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_each_second_counts_in_one_stage_on_the_injected_clock():
    clock = _Clock()
    w = Stopwatch(clock)
    with w.stage("features"):
        clock.t += 1.0
        with w.stage("plan"):  # nested: the outer stage pauses
            clock.t += 0.5
        with w.pause():  # the cell's look: timed by the cell, credited below
            clock.t += 2.0
        w.add("move", 1.5)
        clock.t += 0.25
        w.credit("match", 0.75)  # the recognition's own share of its time
        clock.t += 0.5
    assert w.durations == {"plan": 0.5, "move": 1.5, "match": 0.75, "features": 1.0}
    # every second of the 4.25 s but the look's unmeasured 0.5 s is in exactly one stage
    assert sum(w.durations.values()) == pytest.approx(4.25 - 0.5)


def test_a_restarted_stage_counts_from_the_moment_given():
    clock = _Clock()
    w = Stopwatch(clock)
    with w.stage("wait"):
        with w.pause():
            clock.t += 3.0
        clock.t += 10.0  # the search waited for a part: not this part's time
        w.restart(clock.t - 2.0)  # the part came 2 s ago
    assert w.durations == {"wait": 2.0}


def test_a_stage_left_by_an_exception_is_counted():
    clock = _Clock()
    w = Stopwatch(clock)
    with pytest.raises(RuntimeError), w.stage("pick"):
        clock.t += 0.125
        raise RuntimeError("e-stop")
    with w.stage("pose"):
        clock.t += 1.0
    assert w.durations == {"pick": 0.125, "pose": 1.0}


@pytest.fixture
def url(tmp_path):
    settings = make_settings(tmp_path)
    migrate(settings)
    return settings.database_url


@pytest.mark.parametrize(
    ("retention", "decision", "images"),
    [("all", "recognized", 2), ("failures", "recognized", 0), ("failures", "unknown", 2)],
)
async def test_the_answer_is_what_reading_the_row_back_gives(url, retention, decision, images):
    db = Database(url)
    try:
        cell = await ensure_cell_row(db, "cell-1")
        bus = EventBus()
        events: list[InspectionDone] = []
        bus.add_listener(events.append, InspectionDone)
        ctx = SimpleNamespace(rt=SimpleNamespace(
            database=db, cell_id=cell, bus=bus,
            settings=SimpleNamespace(image_retention=retention),
        ))  # fmt: skip
        draft = InspectionDraft(decision=decision, reason="m scored 0.13 over 2 view(s)",
                                score=0.125, scores={"a": 0.125, "b": 0.0625},
                                viewpoints=(1, 2), pick={"sorted": False, "ok": True,
                                                         "path": (1.0, 2.0)})  # fmt: skip
        draft.views.append(results.ViewRecord(1, b"\xff\xd8jpeg", {"scores": {"a": 0.125}}))
        draft.views.append(results.ViewRecord(2, b"\xff\xd8jpeg", {"scores": {}}))
        draft.cams.append(np.eye(4))
        draft.watch.add("decide", 0.01234)
        opts = InspectOptions(recipe_id=None, recipe_name="r" * 80)
        out = await record.store(ctx, opts, draft, utcnow(), t_start=draft.watch.clock() - 1.5)
        async with db.session() as session:
            back = results.inspection_public(await results.get_inspection(session, out["id"]))
        assert out == back
        assert len(out["images"]) == images
        # the live event is made from the same record
        (ev,) = events
        assert ev.inspection_id == out["id"] and ev.decision == out["decision"] == decision
        assert ev.reason == out["reason"] and ev.viewpoints == (1, 2)
        assert len(ev.T_base_cams) == 1
    finally:
        await db.dispose()


def test_every_event_type_a_client_is_sent_has_one_message():
    done = InspectionDone(7, "recognized", "m", "why", 0.5, (1,), None, ())
    assert _body(done) == {"type": "inspection", "inspection": done.as_dict()}
    assert _body(CellEvent()) is None  # not sent
    assert all(issubclass(t, CellEvent) for t in MESSAGES)
    assert {t.__name__ for t in MESSAGES} >= {
        "ArmState", "JobState", "JobProgress", "CameraStatus", "CellStopped", "InspectionDone"
    }  # fmt: skip


@pytest.mark.parametrize(
    ("key", "value", "why"),
    [
        ("policy", "all", "policy must be one of"),
        ("max_views", 4, "max_views must be an integer in 1..3"),
        ("max_views", True, "max_views must be an integer in 1..3"),
        ("sort", 1, "sort must be true or false"),
        ("speed", 0.0, "speed must be in (0, 1] or null"),
        ("speed", "fast", "speed must be in (0, 1] or null"),
        ("threshold", 1.5, "threshold must be in [0, 1] or null"),
        ("belt_mode", "reverse", "belt_mode must be one of index, continuous or null"),
    ],
)
def test_inspections_and_recipes_check_their_options_by_one_rule(key, value, why):
    with pytest.raises(InvalidInput, match=why.replace("(", r"\(").replace("[", r"\[")):
        InspectOptions(**{key: value})
    with pytest.raises(InvalidInput, match=why.replace("(", r"\(").replace("[", r"\[")):
        RecipeOptions(**{key: value})
