"""vision.recognition: the 2D decision rule (section 3.5.1) on hand-made scores and on small
synthetic images, the score's parts and the homography of the best view."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from tests.vision.recognition_utils import noise, rotated, textured
from vision.recognition import ViewIndex, decide, recognise


@pytest.fixture(scope="module")
def index() -> ViewIndex:
    ix = ViewIndex("sift")
    for seed, model in enumerate(("A", "B", "C")):
        ix.add(model, textured(seed))
    ix.add("A-twin", textured(0))  # looks exactly like A from the top
    return ix


# ------------------------------------------------------------------ the rule on numbers
def test_one_model_above_threshold_is_recognized():
    assert decide({"a": 0.6, "b": 0.05}, threshold=0.2) == ("recognized", "a", ("a",))


def test_two_close_models_are_ambiguous():
    decision, model, contenders = decide({"a": 0.60, "b": 0.55, "c": 0.0}, threshold=0.2)
    assert (decision, model) == ("ambiguous", None)
    assert contenders == ("a", "b")


def test_runner_up_outside_the_margin_does_not_block():
    assert decide({"a": 0.60, "b": 0.40}, threshold=0.2, margin=0.2)[0] == "recognized"
    assert decide({"a": 0.60, "b": 0.40}, threshold=0.2, margin=0.5)[0] == "ambiguous"


def test_nothing_above_threshold_is_unknown():
    assert decide({"a": 0.19, "b": 0.1}, threshold=0.2) == ("unknown", None, ())
    assert decide({}, threshold=0.2) == ("unknown", None, ())
    # strictly above: a score equal to the threshold does not pass
    assert decide({"a": 0.2}, threshold=0.2)[0] == "unknown"


@pytest.mark.parametrize("bad", [math.nan, math.inf, -0.1, 1.5, True, "0.3"])
def test_bad_thresholds_are_refused(bad):
    with pytest.raises(ValueError, match="threshold"):
        decide({"a": 0.5}, threshold=bad)


@pytest.mark.parametrize("bad", [math.nan, 1.0, -0.2])
def test_bad_margins_are_refused(bad):
    with pytest.raises(ValueError, match="margin"):
        decide({"a": 0.5}, threshold=0.1, margin=bad)


def test_scores_outside_unit_interval_are_refused():
    with pytest.raises(ValueError, match="score of 'a'"):
        decide({"a": 1.2}, threshold=0.1)


# ------------------------------------------------------------------ the rule on images
def test_rotated_view_of_one_model_is_recognized_with_its_homography(index):
    angle = 25.0
    query = rotated(textured(1), angle)
    r = recognise(index, query)
    assert r.decision == "recognized" and r.model == "B"
    assert r.score == r.scores["B"] > 0.5
    assert all(r.scores[m] < 0.1 for m in ("A", "A-twin", "C"))
    best = r.best
    assert best is not None and best.view_id == r.view_id
    for part in (best.saturation, best.inlier_ratio, best.coverage, best.clutter):
        assert 0.0 <= part <= 1.0
    assert best.n_inliers >= 10 and best.n_matches >= best.n_inliers
    # H maps trained-view pixels to query pixels: compare with the known rotation.
    M = np.vstack([cv2.getRotationMatrix2D((80, 80), angle, 1.0), [0, 0, 1]])
    pts = np.array([[40.0, 40.0], [120.0, 50.0], [80.0, 120.0]])
    hom = np.c_[pts, np.ones(3)]
    got = (r.H @ hom.T).T
    got = got[:, :2] / got[:, 2:]
    want = (M @ hom.T).T[:, :2]
    assert np.abs(got - want).max() < 1.5


def test_identical_models_give_ambiguous(index):
    r = recognise(index, rotated(textured(0), -20))
    assert r.decision == "ambiguous" and r.model is None
    assert set(r.contenders) == {"A", "A-twin"}
    assert r.best_model in {"A", "A-twin"}


def test_untrained_image_is_unknown(index):
    for q in (noise(7), textured(99)):
        r = recognise(index, q)
        assert r.decision == "unknown" and r.model is None
        assert set(r.scores) == {"A", "A-twin", "B", "C"}
        assert max(r.scores.values()) < 0.1


def test_precomputed_features_give_the_same_result(index):
    query = rotated(textured(2), 10)
    feats = index.features(query)
    a = recognise(index, query)
    b = recognise(index, feats)
    assert (a.decision, a.model) == (b.decision, b.model) == ("recognized", "C")
    assert a.n_features == b.n_features == len(feats)
    with pytest.raises(ValueError, match="mask must be None"):
        recognise(index, feats, mask=np.ones((160, 160), bool))


def test_mask_limits_the_query_features(index):
    query = rotated(textured(1), 5)
    mask = np.zeros(query.shape, bool)
    mask[:, :80] = True
    r = recognise(index, query, mask=mask)
    assert r.n_features < recognise(index, query).n_features
    assert r.model == "B"


def test_models_restriction(index):
    r = recognise(index, rotated(textured(0), 15), models=["A", "C"])
    assert set(r.scores) == {"A", "C"}
    assert r.decision == "recognized" and r.model == "A"


def test_rgb_query_is_accepted(index):
    rgb = np.repeat(rotated(textured(2), 30)[:, :, None], 3, axis=2)
    assert recognise(index, rgb).model == "C"


@pytest.mark.parametrize(
    ("image", "message"),
    [
        (np.zeros((160, 160), np.float32), "uint8"),
        (np.zeros((160, 160, 4), np.uint8), "shape"),
        (np.zeros((8, 8), np.uint8), "16..8192"),
        ([[0, 1], [2, 3]], "numpy array"),
    ],
)
def test_bad_query_images_are_refused(index, image, message):
    with pytest.raises(ValueError, match=message):
        recognise(index, image)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"viewpoint": 4}, "viewpoint"),
        ({"viewpoint": True}, "viewpoint"),
        ({"threshold": math.nan}, "threshold"),
        ({"threshold": math.inf}, "threshold"),
        ({"max_models": 0}, "max_models"),
        ({"views_per_model": 9}, "views_per_model"),
        ({"models": "A"}, "models"),
        ({"mask": np.ones((10, 10), bool)}, "mask shape"),
        ({"mask": np.zeros((160, 160), bool)}, "mask is empty"),
        ({"mask": np.ones((160, 160), np.float64)}, "mask must be"),
    ],
)
def test_bad_options_are_refused(index, kwargs, message):
    with pytest.raises(ValueError, match=message):
        recognise(index, textured(1), **kwargs)


def test_empty_viewpoint_is_unknown(index):
    r = recognise(index, textured(1), viewpoint=2)
    assert r.decision == "unknown" and dict(r.scores) == {}
