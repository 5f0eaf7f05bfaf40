"""vision.recognition: automatic threshold selection (chapter section 6) on synthetic score
distributions with known answers, on a small synthetic index, and its plot."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.vision.recognition_utils import noise, rotated, textured
from vision.recognition import (
    THRESHOLD_FLOOR,
    ThresholdChoice,
    ViewIndex,
    choose_threshold,
    conformal_threshold,
    plot_threshold,
    recognise,
    youden_threshold,
)
from vision.recognition.threshold import roc_curve


def test_conformal_threshold_known_order_statistic():
    imp = np.arange(99) / 100.0  # 0.00 .. 0.98, n = 99
    t, bound = conformal_threshold(imp, 0.01)  # k = ceil(100 * 0.99) = 99
    assert t == pytest.approx(0.98) and bound == pytest.approx(0.01)
    t, bound = conformal_threshold(imp, 0.05)  # k = 95
    assert t == pytest.approx(0.94) and bound == pytest.approx(0.05)
    # shuffled input, same answer
    rng = np.random.default_rng(0)
    assert conformal_threshold(rng.permutation(imp), 0.05)[0] == pytest.approx(0.94)


def test_conformal_threshold_too_few_scores_takes_the_maximum():
    t, bound = conformal_threshold([0.1, 0.3, 0.2], 0.01)  # need 99 scores
    assert t == 0.3 and bound is None


def test_conformal_bound_holds_on_fresh_draws():
    rng = np.random.default_rng(1)
    t, bound = conformal_threshold(rng.beta(2, 8, 2000), 0.02)
    fresh = rng.beta(2, 8, 200_000)
    assert bound <= 0.02
    assert np.mean(fresh > t) <= 0.02 + 0.003


def test_youden_on_separated_and_overlapping_distributions():
    gen = np.linspace(0.6, 1.0, 50)
    imp = np.linspace(0.0, 0.4, 50)
    assert youden_threshold(gen, imp) == pytest.approx(0.4)  # J = 1 from 0.4 on
    # two unit-variance normals at 0.3 and 0.7 (scaled): J is maximal midway
    rng = np.random.default_rng(2)
    g = np.clip(rng.normal(0.7, 0.08, 20_000), 0, 1)
    i = np.clip(rng.normal(0.3, 0.08, 20_000), 0, 1)
    assert youden_threshold(g, i) == pytest.approx(0.5, abs=0.02)


def test_roc_end_points():
    _t, far, tpr = roc_curve([0.5, 0.9], [0.1, 0.2])
    assert far[0] == 1.0 and tpr[0] == 1.0  # accept everything above 0
    assert far[-1] == 0.0 and tpr[-1] == 0.0


@pytest.mark.parametrize("bad", [[np.nan], [1.5], [-0.1], []])
def test_bad_score_lists(bad):
    with pytest.raises(ValueError, match="impostor"):
        conformal_threshold(bad, 0.05)


@pytest.fixture(scope="module")
def index() -> ViewIndex:
    ix = ViewIndex("sift")
    for m in range(3):
        for a in (-20, 0, 20):
            ix.add(f"m{m}", rotated(textured(m), a, 1.0 + a / 200))
    return ix


@pytest.fixture(scope="module")
def choice(index) -> ThresholdChoice:
    return choose_threshold(index, negatives=[noise(s) for s in range(4)], target_far=0.05)


def test_choose_threshold_on_a_synthetic_index(index, choice):
    assert len(choice.genuine) == 9 and len(choice.impostor) == 9 + 4
    assert choice.genuine.min() > choice.impostor.max()  # the synthetic models are distinct
    # 13 impostor scores cannot certify 5 % (needs 19): the maximum is taken and said so
    assert choice.far_bound is None and "not reachable" in choice.rule
    # ... raised to the floor when that maximum is below it (an automatic threshold is never
    # a chance-match level)
    assert choice.threshold == pytest.approx(max(choice.impostor.max(), THRESHOLD_FLOOR))
    assert choice.far == 0.0 and choice.frr == 0.0
    assert set(choice.per_model) == {"m0", "m1", "m2"}
    assert all(t >= choice.threshold for t in choice.per_model.values())
    # nothing is confused with anything
    assert all(v == 0.0 for row in choice.confusion[1].values() for v in row.values())
    r = recognise(index, rotated(textured(1), 10), threshold=choice)
    assert r.model == "m1" and r.threshold == choice.per_model["m1"]
    assert recognise(index, noise(50), threshold=choice).decision == "unknown"


def test_youden_rule_and_progress(index):
    seen = []
    ch = choose_threshold(index, rule="youden", progress=lambda d, t: seen.append((d, t)))
    assert ch.rule_id == "youden" and ch.target_far is None
    assert seen[-1][0] == seen[-1][1] == 18
    assert ch.impostor.max() <= ch.threshold < ch.genuine.min()


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"target_far": 0.0}, "target_far"),
        ({"target_far": math.nan}, "target_far"),
        ({"target_far": True}, "target_far"),
        ({"target_far": 0.9}, "target_far"),
        ({"rule": "guess"}, "rule"),
        ({"negatives": [np.zeros((4, 4), np.uint8)]}, "16..8192"),
    ],
)
def test_bad_choices(index, kwargs, message):
    with pytest.raises(ValueError, match=message):
        choose_threshold(index, **kwargs)


def test_one_model_is_not_enough():
    ix = ViewIndex("sift")
    ix.add("only", textured(0))
    ix.add("only", textured(0))
    with pytest.raises(ValueError, match="two models"):
        choose_threshold(ix)


def test_plot_writes_a_small_png(choice, tmp_path):
    path = plot_threshold(choice, tmp_path / "sub" / "t.png", title="synthetic", unknown=[0.01])
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and 5_000 < len(data) < 300_000
    with pytest.raises(ValueError, match="dpi"):
        plot_threshold(choice, tmp_path / "x.png", dpi=1000)


def test_own_bars_are_at_most_the_viewpoint_bar_and_fall_back_with_few_scores():
    """Own bars (issue 14): each model's bar from its own impostor scores, capped by the
    viewpoint's bar; a model with fewer than MIN_OWN_IMPOSTORS scores gets the viewpoint's."""
    from tests.vision.recognition_utils import rotated, textured
    from vision.recognition import ViewIndex, choose_threshold
    from vision.recognition.threshold import MIN_OWN_IMPOSTORS

    ix = ViewIndex("sift")
    n_models, n_views = 6, 4  # 5 * 4 = 20 impostor views per model at the top
    for k in range(n_models):
        for a in range(n_views):
            ix.add(f"M{k}", rotated(textured(50 + k), 15.0 * a - 20.0), viewpoint=1)
    ch = choose_threshold(ix, target_far=0.1)
    assert (n_models - 1) * n_views >= MIN_OWN_IMPOSTORS
    own = ch.own_viewpoint[1]
    assert set(own) == set(ix.models)
    assert all(0.0 <= t <= ch.per_viewpoint[1] for t in own.values())
    assert min(own.values()) < ch.per_viewpoint[1]  # the global is set by one model only
    assert ch.own("M0", 1) == own["M0"] and ch.at(1).own_viewpoint == {}
    # Three views per model: 6 impostor scores each, too few: the viewpoint's bar.
    small = ViewIndex("sift")
    for k in range(3):
        for a in range(3):
            small.add(f"M{k}", rotated(textured(50 + k), 15.0 * a - 20.0), viewpoint=1)
    ch = choose_threshold(small, target_far=0.1)
    assert ch.own_viewpoint[1] == {m: ch.per_viewpoint[1] for m in small.models}


def test_own_bar_of_a_model_that_verified_nothing_is_the_pooled_bar_not_zero():
    from vision.recognition.threshold import MIN_OWN_IMPOSTORS, _own_bars

    n = MIN_OWN_IMPOSTORS
    imp = {
        "plain": [0.0] * n,  # verified none of the other models' views
        "wheel": [0.0] * (n - 3) + [0.2, 0.25, 0.3],  # verifies other wheels
        "few": [0.0] * (n - 1),  # too few scores: the viewpoint's bar
    }
    got = _own_bars(imp, list(imp), 0.3, rule="conformal-far", target_far=0.05)
    pooled = sorted(s for v in imp.values() for s in v)
    k = int(np.ceil((len(pooled) + 1) * 0.95 - 1e-9))
    assert got["plain"] == pooled[k - 1] > 0.0
    assert got["wheel"] == 0.3 and got["few"] == 0.3
    assert _own_bars(imp, list(imp), 0.3, rule="youden", target_far=0.05) == dict.fromkeys(imp, 0.3)


def test_one_model_with_negatives_gets_a_floored_threshold_and_advice():
    ix = ViewIndex("sift")
    for a in (-15, 0, 15):
        ix.add("only", rotated(textured(3), a))
    with pytest.raises(ValueError, match="two models, or one model and negative images"):
        choose_threshold(ix)
    ch = choose_threshold(ix, negatives=[noise(s) for s in range(3)] + [textured(9)])
    assert len(ch.genuine) == 3 and len(ch.impostor) == 4  # the negatives alone
    assert ch.threshold >= THRESHOLD_FLOOR and ch.per_model["only"] >= ch.threshold
    assert ch.genuine.min() > ch.threshold
    text = " ".join(ch.advice)
    assert "Add impostors" in text and "Only one model" in text
    r = recognise(ix, rotated(textured(3), 7), threshold=ch)
    assert r.model == "only"
    assert recognise(ix, textured(10), threshold=ch).decision == "unknown"


def test_no_advice_when_the_data_supports_the_target(index):
    negs = [noise(s) for s in range(120)]
    ch = choose_threshold(index, negatives=negs, target_far=0.05)
    assert ch.far_bound is not None and not any("Add impostors" in a for a in ch.advice)
