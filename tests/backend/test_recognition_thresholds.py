"""The automatic threshold stored and read back: per-model, per-viewpoint and override."""

from __future__ import annotations

import asyncio

from backend.db.models import ObjectKind, ObjectModel, RecognitionSettings
from backend.db.session import Database
from backend.recognition.thresholds import choice_from_detail, current_choice
from vision.recognition import ThresholdChoice


def test_stored_choice_round_trips_and_model_thresholds_override(settings):
    detail = {
        "rule": "conformal",
        "rule_id": "conformal-far",
        "per_model": {"a": 0.3, "b": 0.35},
        "per_viewpoint": {"1": 0.25, "2": 0.4},
        "per_model_viewpoint": {"1": {"a": 0.26}, "2": {"b": 0.45}},
        "candidate": 0.1,
        "candidate_viewpoint": {"1": 0.12},
        "own_viewpoint": {"2": {"a": 0.2, "b": 0.4}},
        "genuine": [0.8, 0.9],
        "impostor": [0.1, 0.2],
        "genuine_models": ["a", "b"],
        "confusion": {"1": {"a": {"b": 0.5}}},
        "far": 0.0,
        "frr": 0.0,
    }
    choice = choice_from_detail(0.3, detail)
    assert isinstance(choice, ThresholdChoice)
    assert choice.at(1).threshold == 0.25 and choice.at(1).per_model == {"a": 0.26}
    assert choice.at(2).per_model == {"b": 0.45} and choice.confusion[1]["a"]["b"] == 0.5
    assert choice.own("a", 2) == 0.2 and choice.own("b", 1) == 0.25  # no own bars at 1

    async def run() -> ThresholdChoice:
        db = Database(settings.database_url)
        try:
            async with db.session() as s:
                s.add(RecognitionSettings(global_threshold=0.3, chosen_by="auto", detail=detail))
                s.add(ObjectModel(name="a", part="a", kind=ObjectKind.two_d, threshold=0.7))
            async with db.session() as s:
                return await current_choice(s)
        finally:
            await db.dispose()

    got = asyncio.run(run())
    assert got.per_model["a"] == 0.7 and got.per_model["b"] == 0.35
    assert got.at(1).per_model["a"] == 0.7 and got.at(2).per_model == {"b": 0.45, "a": 0.7}
    assert got.at(1).threshold == 0.25
    assert got.own("a", 2) == 0.7 and got.own("b", 2) == 0.4  # the override replaces own bars
