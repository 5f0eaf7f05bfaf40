"""Characterisation of ``recognise_views``: every policy, on a fixed grid of inputs, gives
the outcomes recorded in ``data/recognise_views_outcomes.json``.

The record pins what the viewpoint policies do (decision, model, fused scores, contenders,
the viewpoints visited and in which order, which models each view was searched against,
which thresholds it was given, when the colour tie-break was consulted, and the errors
refused), so that the policies' code can be reorganised without changing their behaviour.

Two kinds of case:

- *scripted*: ``recognise`` is replaced by one that answers the scores scripted for the
  viewpoint the camera looked at (the image carries it), restricted to the models asked
  for, with the real decision rule applied; ``colour_support`` answers scripted colour
  distances. A grid of score scripts, thresholds (none, a number, threshold choices with
  look-alikes, own bars, a lowered candidate bar, top-view confusion), view budgets, and
  colour answers reaches the branches of every policy.
- *real*: the SIFT index of ``test_recognition_views`` and its scripted camera, including a
  ``look`` that returns an ``(image, mask)`` pair or features; scores rounded to 3 decimals.

The record was written once from the code before its policies became objects; a case
whose outcome differs fails with the case name and both outcomes.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np
import pytest

from tests.vision.recognition_utils import noise, rotated, textured
from vision.recognition import Recognition, ThresholdChoice, ViewIndex, recognise_views
from vision.recognition import views as views_module
from vision.recognition.recognise import decide

RECORD = Path(__file__).parent / "data" / "recognise_views_outcomes.json"
POLICIES = ("naive", "top-only", "two-views", "best-next")

# --- scripted cases ------------------------------------------------------------------------

#: Models A, B, C have trained views at every viewpoint; D only from the top.
SIDED = ("A", "B", "C")
TOP_BAR, SIDE_BAR = 0.107, 0.264

SCRIPTS: dict[str, dict[int, dict[str, float]]] = {
    "clear-top-blank-sides": {1: {"A": 0.295}},
    "top-confirmed-side2": {1: {"A": 0.295}, 2: {"A": 0.30}, 3: {"A": 0.5}},
    "challengers": {1: {"A": 0.295, "B": 0.15, "C": 0.05}},
    "contradicted": {1: {"A": 0.295, "B": 0.15}, 2: {"B": 0.30, "A": 0.02}},
    "contradicted-narrowly": {1: {"A": 0.295, "B": 0.15}, 2: {"B": 0.27, "A": 0.26}},
    "weak-side2-strong-side3": {1: {"A": 0.295}, 2: {"A": 0.05}, 3: {"A": 0.40}},
    "shortlisted-untrained": {1: {"A": 0.09, "B": 0.07}, 2: {"A": 0.10}, 3: {"B": 0.12}},
    "top-twins-blank-sides": {1: {"A": 0.295, "B": 0.28}},
    "below-top-bar": {1: {"A": 0.08}, 2: {"A": 0.9}},
    "plain-part-own-bars": {1: {"C": 0.073}, 2: {"C": 0.15}, 3: {"C": 0.12}},
    "untrained-own-bars": {1: {"C": 0.05}, 2: {"C": 0.06}, 3: {"C": 0.07}},
    "prone-model": {1: {"A": 0.09}, 2: {"A": 0.2}, 3: {"A": 0.2}},
    "grey-lookalike-favoured": {
        1: {"A": 0.5, "B": 0.35},
        2: {"A": 0.2, "B": 0.6},
        3: {"A": 0.2, "B": 0.6},
    },
    "ambiguous-top-lookalike": {
        1: {"A": 0.5, "B": 0.49},
        2: {"A": 0.1, "B": 0.47},
        3: {"A": 0.1, "B": 0.45},
    },
    "twin-below-own-bar": {
        1: {"B": 0.5, "A": 0.35},
        2: {"B": 0.4, "A": 0.2},
        3: {"A": 0.5, "B": 0.45},
    },
    "twin-above-own-bar": {
        1: {"B": 0.5, "A": 0.35},
        2: {"B": 0.4, "A": 0.3},
        3: {"A": 0.5, "B": 0.45},
    },
    "twin-outside-margin": {
        1: {"A": 0.6, "B": 0.49},
        2: {"A": 0.25, "B": 0.05},
        3: {"A": 0.25, "B": 0.27},
    },
    "twin-never-passes": {
        1: {"A": 0.6, "B": 0.49},
        2: {"A": 0.25, "B": 0.05},
        3: {"A": 0.25, "B": 0.2},
    },
    "named-beside-lookalike": {
        1: {"B": 0.773, "A": 0.579},
        2: {"A": 0.207, "B": 0.249},
        3: {"A": 0.3, "B": 0.25},
    },
    "three-way-top": {
        1: {"A": 0.5, "B": 0.48, "C": 0.47},
        2: {"C": 0.5, "A": 0.3},
        3: {"B": 0.4, "C": 0.41},
    },
    "rival-on-side3": {1: {"A": 0.6, "B": 0.2}, 2: {"A": 0.1}, 3: {"B": 0.6, "A": 0.1}},
    "naive-on-side2": {1: {"A": 0.5, "B": 0.49}, 2: {"B": 0.6}},
    "nothing": {},
    "top-only-model": {1: {"D": 0.5}},
    "top-only-model-and-twin": {1: {"D": 0.5, "A": 0.49}, 2: {"A": 0.4}},
    "all-side-no-top": {2: {"A": 0.9}, 3: {"B": 0.9}},
}


def _choice(**changes: Any) -> ThresholdChoice:
    base = ThresholdChoice(
        threshold=TOP_BAR,
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
        confusion={},
        candidate=TOP_BAR,
        per_viewpoint={1: TOP_BAR, 2: SIDE_BAR, 3: SIDE_BAR},
        per_model_viewpoint={1: {}, 2: {}, 3: {}},
        candidate_viewpoint={1: TOP_BAR, 2: SIDE_BAR, 3: SIDE_BAR},
    )
    return replace(base, **changes)


def _confused(share: float) -> dict[int, dict[str, dict[str, float]]]:
    row = {"A": {"B": share}, "B": {"A": share}}
    return {1: row, 2: row, 3: row}


def _own() -> dict[int, dict[str, float]]:
    own = {1: {"A": TOP_BAR, "B": TOP_BAR, "C": 0.03}, 2: {"A": SIDE_BAR, "B": SIDE_BAR, "C": 0.08}}
    own[3] = dict(own[2])
    return own


THRESHOLDS: dict[str, Callable[[], float | ThresholdChoice | None]] = {
    "default": lambda: None,
    "number": lambda: 0.15,
    "choice": lambda: _choice(),
    "lookalikes": lambda: _choice(confusion=_confused(0.9)),
    "distinct": lambda: _choice(confusion=_confused(0.1)),
    "own-bars": lambda: _choice(own_viewpoint=_own()),
    "low-candidate": lambda: _choice(
        own_viewpoint=_own(), candidate_viewpoint={1: 0.05, 2: SIDE_BAR, 3: SIDE_BAR}
    ),
    "top-confusion": lambda: _choice(
        confusion={
            1: {"A": {"B": 0.2}, "C": {"A": 0.06}, "D": {"A": 0.5}},
            2: {"A": {"B": 0.6, "C": 0.1}, "B": {"A": 0.7}},
            3: {"A": {"B": 0.0}, "B": {"A": 0.0}},
        }
    ),
}

#: Colour answers: ``None`` keeps the real ``colour_support`` (scripted views carry no
#: candidates, so it finds no colour); ``False`` turns the tie-break off.
COLOURS: dict[str, dict[str, float] | bool | None] = {
    "off": False,
    "real": None,
    "A": {"A": 0.0, "B": 2.4, "C": 3.0},
    "B": {"A": 2.4, "B": 0.0},
    "close": {"A": 0.5, "B": 0.6, "C": 0.55},
    "far": {"A": 2.5, "B": 2.4},
}


def _threshold_summary(threshold: object) -> object:
    if isinstance(threshold, ThresholdChoice):
        return [threshold.threshold, sorted(threshold.per_model.items())]
    return threshold


@contextmanager
def _scripted(per_view: dict[int, dict[str, float]], dist: dict[str, float] | None):
    """Replace ``recognise`` (and ``colour_support`` when ``dist`` is given) in the views
    module; yields the list of calls made to them."""
    calls: list[list[object]] = []

    def fake(index, image, *, viewpoint, threshold, margin, models=None, mask=None, search=None):
        looked = int(image[0, 0])  # the viewpoint the camera looked from (see _look)
        names = index.models if models is None else [m for m in index.models if m in models]
        scores = {m: float(per_view.get(looked, {}).get(m, 0.0)) for m in names}
        calls.append(
            [
                "recognise",
                looked,
                viewpoint,
                names,
                _threshold_summary(threshold),
                margin,
                None if search is None else list(search),
                mask is None,
            ]
        )
        decision, model, cont = decide(scores, threshold=threshold, margin=margin)
        best = max(scores, key=lambda m: (scores[m], m), default=None)
        return Recognition(
            decision=decision,
            model=model,
            best_model=best if best is not None and scores[best] > 0 else None,
            score=scores.get(best, 0.0) if best is not None else 0.0,
            scores=MappingProxyType(scores),
            contenders=cont,
            candidates=(),
            threshold=TOP_BAR,
            margin=margin,
            viewpoint=viewpoint,
            n_features=100,
            retrieval_s=0.0,
            verification_s=0.0,
        )

    def colour(index, views, images, models):
        calls.append(["colour", [r.viewpoint for r in views], list(models)])
        assert dist is not None
        return {m: dist[m] for m in models if m in dist}

    saved = views_module.recognise, views_module.colour_support
    views_module.recognise = fake  # type: ignore[assignment]
    if dist is not None:
        views_module.colour_support = colour  # type: ignore[assignment]
    try:
        yield calls
    finally:
        views_module.recognise, views_module.colour_support = saved


def _marked_look(vp: int) -> np.ndarray:
    image = textured(99, size=32)
    image[0, 0] = vp
    return image


def _outcome(r) -> dict[str, object]:
    return {
        "decision": r.decision,
        "model": r.model,
        "score": round(r.score, 12),
        "scores": sorted((m, round(v, 12)) for m, v in r.scores.items()),
        "contenders": list(r.contenders),
        "policy": r.policy,
        "viewpoints": list(r.viewpoints),
        "views": [[v.viewpoint, v.decision, v.model, list(v.contenders)] for v in r.views],
        "n_views": r.n_views,
    }


def _scripted_cases() -> Iterator[tuple[str, dict[str, Any]]]:
    grid: list[tuple[str, tuple[str, ...], tuple[tuple[int, str], ...]]] = [
        # Naive and top-only never consult colour; best-next refuses a threshold that is
        # not a choice, so those cases record the refusal.
        ("naive", ("default", "number", "choice", "own-bars"), ((1, "off"), (3, "off"))),
        ("top-only", ("default", "number", "choice", "own-bars"), ((3, "off"),)),
        *(
            (policy, tuple(THRESHOLDS), ((3, "off"), (3, "A"), (3, "B"), (3, "close"), (2, "A")))
            for policy in ("two-views", "best-next")
        ),
    ]
    for policy, thresholds, budgets in grid:
        for script in SCRIPTS:
            for th in thresholds:
                for max_views, colour in budgets:
                    yield (
                        f"{script}|{policy}|{th}|{max_views}|{colour}",
                        {
                            "script": script,
                            "policy": policy,
                            "threshold": th,
                            "max_views": max_views,
                            "colour": colour,
                        },
                    )
    for th, colour in (("choice", "real"), ("lookalikes", "real"), ("lookalikes", "far")):
        for script in SCRIPTS:
            yield (
                f"{script}|two-views|{th}|3|{colour}",
                {
                    "script": script,
                    "policy": "two-views",
                    "threshold": th,
                    "max_views": 3,
                    "colour": colour,
                },
            )
    for policy in POLICIES:
        yield (
            f"twin-outside-margin|{policy}|choice|1|off",
            {
                "script": "twin-outside-margin",
                "policy": policy,
                "threshold": "choice",
                "max_views": 1,
                "colour": "off",
            },
        )
    for name, margin in (("wide-margin", 0.3), ("no-margin", 0.0)):
        for script in ("ambiguous-top-lookalike", "twin-outside-margin", "three-way-top"):
            for policy in POLICIES:
                yield (
                    f"{script}|{policy}|lookalikes|3|A|{name}",
                    {
                        "script": script,
                        "policy": policy,
                        "threshold": "lookalikes",
                        "max_views": 3,
                        "colour": "A",
                        "margin": margin,
                    },
                )
    yield (
        "limit-0",
        {
            "script": "challengers",
            "policy": "best-next",
            "threshold": "top-confusion",
            "max_views": 3,
            "colour": "A",
            "confusion_limit": 0.0,
        },
    )
    yield (
        "limit-1",
        {
            "script": "challengers",
            "policy": "best-next",
            "threshold": "top-confusion",
            "max_views": 3,
            "colour": "A",
            "confusion_limit": 1.0,
        },
    )


async def _run_scripted(index: ViewIndex, case: dict[str, Any]) -> dict[str, object]:
    colour = COLOURS[case["colour"]]
    dist = colour if isinstance(colour, dict) else None
    kwargs: dict[str, Any] = {
        "policy": case["policy"],
        "max_views": case["max_views"],
        "threshold": THRESHOLDS[case["threshold"]](),
        "colour_tiebreak": colour is not False,
    }
    for key in ("margin", "confusion_limit"):
        if key in case:
            kwargs[key] = case[key]
    with _scripted(SCRIPTS[case["script"]], dist) as calls:
        try:
            r = await recognise_views(_marked_look, index, **kwargs)
        except ValueError as exc:
            return {"error": type(exc).__name__, "detail": str(exc), "calls": calls}
        out = _outcome(r)
        del out["views"]  # the calls record what each view was asked and the script answers
        return {**out, "calls": calls}


def build_scripted_index() -> ViewIndex:
    """A, B, C trained at every viewpoint, D from the top only (contents never matched)."""
    ix = ViewIndex("sift")
    for k, m in enumerate(SIDED):
        for vp in (1, 2, 3):
            ix.add(m, textured(10 * k + vp), viewpoint=vp)
    ix.add("D", textured(77), viewpoint=1)
    return ix


@pytest.fixture(scope="module")
def scripted_index() -> ViewIndex:
    return build_scripted_index()


# --- real cases ------------------------------------------------------------------------------

TOP = {"A": 0, "B": 0, "C": 2}
SIDE = {("A", 2): 10, ("A", 3): 11, ("B", 2): 20, ("B", 3): 21, ("C", 2): 30, ("C", 3): 31}


def _real_image(model: str | None, vp: int) -> np.ndarray:
    if model is None:
        return noise(100 + vp)
    seed = TOP[model] if vp == 1 else SIDE[(model, vp)]
    return rotated(textured(seed), 12.0 * vp - 18.0)


def build_real_indexes() -> dict[str, ViewIndex]:
    """The indexes of ``test_recognition_views``: one view per model and viewpoint, and
    two per model and viewpoint with A and B alike from the top."""
    plain = ViewIndex("sift")
    for m, seed in TOP.items():
        plain.add(m, textured(seed), viewpoint=1)
    for (m, vp), seed in SIDE.items():
        plain.add(m, textured(seed), viewpoint=vp)
    twin = ViewIndex("sift")
    for m in ("A", "B", "C"):
        for angle in (-10.0, 10.0):
            twin.add(m, rotated(textured(TOP[m]), angle), viewpoint=1)
            for vp in (2, 3):
                twin.add(m, rotated(textured(SIDE[(m, vp)]), angle), viewpoint=vp)
    return {"plain": plain, "twin": twin}


@pytest.fixture(scope="module")
def real_indexes() -> dict[str, ViewIndex]:
    return build_real_indexes()


def _real_outcome(r) -> dict[str, object]:
    out = _outcome(r)
    out["score"] = round(r.score, 3)
    out["scores"] = sorted((m, round(v, 3)) for m, v in r.scores.items())
    out["views"] = [
        [v.viewpoint, v.decision, v.model, list(v.contenders), sorted(v.scores)] for v in r.views
    ]
    return out


async def _real_outcomes(indexes: dict[str, ViewIndex]) -> dict[str, object]:
    from vision.recognition import choose_threshold

    confusion = {
        1: {"A": {"B": 1.0, "C": 0.0}, "B": {"A": 1.0, "C": 0.0}, "C": {"A": 0.0, "B": 0.0}},
        2: {"A": {"B": 0.5}, "B": {"A": 0.5}},
        3: {"A": {"B": 0.0}, "B": {"A": 0.0}},
    }
    thresholds: dict[str, Any] = {
        "default": None,
        "hand": replace(
            _choice(threshold=0.1),
            candidate=0.1,
            per_viewpoint={},
            per_model_viewpoint={},
            candidate_viewpoint={},
            confusion=confusion,
        ),
        "chosen": choose_threshold(indexes["twin"], target_far=0.1),
    }
    grid = {"plain": ("default", "hand"), "twin": ("chosen",)}
    out: dict[str, object] = {}
    for ix_name, ix in indexes.items():
        for model in ("A", "B", "C", None):
            for policy in POLICIES:
                for th_name in grid[ix_name]:
                    name = f"real|{ix_name}|{model}|{policy}|{th_name}"
                    asked: list[int] = []

                    def look(vp: int, model=model, asked=asked) -> np.ndarray:
                        asked.append(vp)
                        return _real_image(model, vp)

                    try:
                        r = await recognise_views(
                            look, ix, policy=policy, threshold=thresholds[th_name]
                        )
                    except ValueError as exc:
                        out[name] = {"error": str(exc), "asked": asked}
                        continue
                    out[name] = {**_real_outcome(r), "asked": asked}
    plain = indexes["plain"]
    img = _real_image("C", 1)
    r = await recognise_views(lambda vp: (img, np.ones(img.shape, bool)), plain, policy="top-only")
    out["real|mask"] = _real_outcome(r)
    feats = plain.features(img)
    r = await recognise_views(lambda vp: feats, plain, policy="two-views", max_views=1)
    out["real|features"] = _real_outcome(r)
    return out


# --- refused arguments ------------------------------------------------------------------------

BAD_ARGUMENTS: dict[str, dict[str, Any]] = {
    "policy": {"policy": "random"},
    "max-views-0": {"policy": "naive", "max_views": 0},
    "max-views-4": {"policy": "naive", "max_views": 4},
    "max-views-bool": {"policy": "naive", "max_views": True},
    "max-views-float": {"policy": "naive", "max_views": 2.0},
    "best-next-number": {"policy": "best-next", "threshold": 0.2},
    "threshold-nan": {"policy": "naive", "threshold": float("nan")},
    "margin": {"policy": "two-views", "margin": 1.0},
    "limit-negative": {"policy": "two-views", "confusion_limit": -0.1},
    "limit-bool": {"policy": "two-views", "confusion_limit": True},
    "limit-text": {"policy": "two-views", "confusion_limit": "0.1"},
    "tiebreak": {"policy": "two-views", "colour_tiebreak": 1},
}


async def _refusals(index: ViewIndex) -> dict[str, object]:
    out: dict[str, object] = {}
    for name, kwargs in BAD_ARGUMENTS.items():
        asked: list[int] = []

        def look(vp: int, asked=asked) -> np.ndarray:
            asked.append(vp)
            return textured(1)

        with pytest.raises(ValueError) as exc:
            await recognise_views(look, index, **kwargs)
        out[f"refused|{name}"] = {"detail": str(exc.value), "asked": asked}
    for name, bad in (("index", "index"), ("look", "look")):
        args: list[Any] = [lambda vp: textured(1), index]
        args[0 if bad == "look" else 1] = 42
        with pytest.raises(ValueError) as exc:
            await recognise_views(*args, policy="naive")
        out[f"refused|{name}"] = {"detail": str(exc.value)}
    for name, look in (
        ("junk", lambda vp: "picture"),
        ("triple", lambda vp: (textured(1), None, None)),
    ):
        for policy in POLICIES[:3]:
            with pytest.raises(ValueError) as exc:
                await recognise_views(look, index, policy=policy)
            out[f"refused|{name}|{policy}"] = {"detail": str(exc.value)}
    return out


async def outcomes(scripted_index: ViewIndex, real_indexes: dict[str, ViewIndex]) -> dict:
    """Every case's outcome, JSON-shaped (what the record holds)."""
    out: dict[str, object] = {}
    for name, case in _scripted_cases():
        out[name] = await _run_scripted(scripted_index, case)
    out.update(await _real_outcomes(real_indexes))
    out.update(await _refusals(scripted_index))
    return json.loads(json.dumps(out))


async def test_recognise_views_keeps_its_recorded_outcomes(scripted_index, real_indexes):
    record = json.loads(RECORD.read_text())
    got = await outcomes(scripted_index, real_indexes)
    assert sorted(got) == sorted(record), "the grid of cases differs from the record's"
    differ = [name for name in record if got[name] != record[name]]
    shown = "\n".join(
        f"{name}\n  recorded {record[name]}\n  now      {got[name]}" for name in differ[:5]
    )
    assert not differ, f"{len(differ)} of {len(record)} cases changed:\n{shown}"
    # The grid reaches every outcome of each policy it is meant to pin.
    decisions = {(v["policy"], v["decision"]) for v in record.values() if "decision" in v}
    for policy in POLICIES:
        for decision in ("recognized", "ambiguous", "unknown"):
            assert (policy, decision) in decisions
