"""The recognition benchmark's helpers: the eigenspace baseline, brute force and the
multi-view scenarios."""

from __future__ import annotations

import numpy as np

from benchmarks import recognition as bench
from benchmarks import recognition_data as rd
from tests.vision.recognition_utils import rotated, textured
from vision.recognition import ViewIndex


def test_eigenspace_recovers_training_images_and_near_copies():
    images = [textured(s, 64) for s in range(6)]
    labels = [f"m{s}" for s in range(6)]
    eig = rd.Eigenspace(images, labels, n_components=4)
    assert [eig.predict(i) for i in images] == labels
    # brightness normalisation: a darker copy is still the same model
    assert eig.predict((images[3] * 0.6).astype(np.uint8)) == "m3"


def test_brute_force_scores_every_model():
    ix = ViewIndex("sift")
    feats = {m: ix.features(textured(s)) for s, m in enumerate("AB")}
    q = ix.features(rotated(textured(1), 20))
    scores = rd.brute_force([("A", feats["A"]), ("B", feats["B"])], q, geometry="affine")
    assert set(scores) == {"A", "B"} and scores["B"] > 0.5 > scores["A"]


def test_scenarios_pair_the_twin_tops_and_present_untrained_objects():
    sc = bench.scenarios()
    layout, trials = sc["coil"]
    assert len(layout) == 10 and sum(t is None for t, _ in trials) == 5
    layout, trials = sc["twin-tops"]
    tops = [vps[1] for vps in layout.values()]
    assert sorted(tops) == [1, 1, 2, 2, 3, 3, 4, 4, 5, 5]
    assert len({vps[2] for vps in layout.values()}) == 10
    untrained = [vps for t, vps in trials if t is None]
    assert len(untrained) == 5
    trained = {(v[1], v[2]) for v in layout.values()}
    assert all((v[1], v[2]) not in trained for v in untrained)
