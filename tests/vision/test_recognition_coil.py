"""vision.recognition on a handful of real COIL-20 images (Nene, Nayar and Murase 1996):
views 5 degrees from the trained ones are recognised, an untrained object is not."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from vision.recognition import ViewIndex, choose_threshold, recognise

OBJECTS = (1, 3, 5, 8)


@pytest.fixture(scope="module")
def coil(data_dir) -> Path:
    folder = data_dir / "recognition" / "coil20"
    if not (folder / "obj1__0.png").is_file():
        pytest.skip(f"COIL-20 images are absent from {folder} (see the data README)")
    return folder


def _img(folder: Path, obj: int, k: int) -> np.ndarray:
    return cv2.imread(str(folder / f"obj{obj}__{k}.png"), cv2.IMREAD_GRAYSCALE)


@pytest.fixture(scope="module")
def index(coil) -> ViewIndex:
    ix = ViewIndex("sift")
    for o in OBJECTS:
        for k in (0, 4, 8):  # 0, 20 and 40 degrees
            ix.add(f"obj{o}", _img(coil, o, k))
    return ix


def test_real_views_between_trained_ones_are_recognised(index, coil):
    choice = choose_threshold(index, target_far=0.1)
    for o in OBJECTS:
        for k in (2, 6):  # 10 and 30 degrees: 10 degrees from a trained view
            r = recognise(index, _img(coil, o, k), threshold=choice)
            assert r.best_model == f"obj{o}", (o, k, dict(r.scores))
            assert r.H is not None and r.H.shape == (3, 3)


def test_untrained_real_object_scores_low(index, coil):
    scores = [max(recognise(index, _img(coil, 12, k)).scores.values()) for k in (0, 18, 36)]
    assert max(scores) < 0.15
