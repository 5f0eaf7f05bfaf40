"""vision.recognition.policies: the policy objects, their registry, and a policy run
directly over a ViewState (what ``recognise_views`` does after validating its arguments)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.vision.recognition_utils import rotated, textured
from vision.recognition import POLICIES, ThresholdChoice, ViewIndex, recognise, recognise_views
from vision.recognition.policies import POLICY_OBJECTS, BestNext, TwoViews
from vision.recognition.views import colour_support
from vision.recognition.viewstate import ViewState

TOP = {"A": 0, "B": 0, "C": 2}  # A and B alike from the top
SIDE = {"A": 10, "B": 20, "C": 30}


@pytest.fixture(scope="module")
def index() -> ViewIndex:
    ix = ViewIndex("sift")
    for m in TOP:
        ix.add(m, textured(TOP[m]), viewpoint=1)
        ix.add(m, textured(SIDE[m]), viewpoint=2)
    return ix


def _look(model: str):
    def look(vp: int):
        return rotated(textured(TOP[model] if vp == 1 else SIDE[model]), 8.0 * vp)

    return look


def test_registry_holds_one_object_per_policy_in_order():
    assert POLICIES == ("naive", "top-only", "two-views", "best-next") == tuple(POLICY_OBJECTS)
    assert all(POLICY_OBJECTS[name].name == name for name in POLICIES)
    assert [name for name in POLICIES if POLICY_OBJECTS[name].needs_choice] == ["best-next"]
    assert isinstance(POLICY_OBJECTS["best-next"], TwoViews)


async def test_a_policy_run_over_a_state_answers_as_recognise_views(index):
    calls: list[tuple[int | None, tuple[str, ...] | None]] = []

    def counted(ix, image, **kwargs):
        models = kwargs["models"]
        calls.append((kwargs["viewpoint"], None if models is None else tuple(models)))
        return recognise(ix, image, **kwargs)

    state = ViewState(
        look=_look("B"),
        index=index,
        policy="two-views",
        max_views=3,
        threshold=None,
        margin=0.2,
        confusion_limit=0.05,
        colour_tiebreak=True,
        recognise=counted,
        colour_support=colour_support,
    )
    direct = await POLICY_OBJECTS["two-views"].run(state)
    public = await recognise_views(_look("B"), index, policy="two-views")
    assert (direct.decision, direct.model, direct.viewpoints) == ("recognized", "B", (1, 2))
    assert (public.decision, public.model, public.viewpoints) == ("recognized", "B", (1, 2))
    assert dict(direct.scores) == pytest.approx(dict(public.scores))
    # The state holds the views taken: the top view against every model, the side view
    # against the top view's contenders.
    assert state.visited == [1, 2] and len(state.views) == 2
    assert calls == [(1, None), (2, ("A", "B"))]


def test_best_next_visits_the_least_confused_side_first():
    sided = ViewIndex("sift")
    for m in TOP:
        for vp in (1, 2, 3):
            sided.add(m, textured(TOP[m] if vp == 1 else SIDE[m] + vp), viewpoint=vp)
    choice = ThresholdChoice(
        threshold=0.1,
        per_model={},
        rule="hand-made",
        rule_id="conformal-far",
        target_far=0.01,
        far_bound=None,
        far=0.0,
        frr=0.0,
        genuine=np.array([0.5]),
        impostor=np.array([0.0]),
        genuine_models=("A",),
        confusion={2: {"A": {"B": 0.4}}, 3: {"A": {"B": 0.1}}},  # A, B: less alike from 3
    )
    state = ViewState(
        look=_look("A"),
        index=sided,
        policy="best-next",
        max_views=3,
        threshold=choice,
        margin=0.2,
        confusion_limit=0.05,
        colour_tiebreak=True,
        recognise=recognise,
        colour_support=colour_support,
    )
    assert BestNext().side_order(state, ("A", "B")) == [3, 2]
    assert TwoViews().side_order(state, ("A", "B")) == [2, 3]
    assert BestNext().side_order(state, ("A", "C")) == [2, 3]  # not confused: in order
