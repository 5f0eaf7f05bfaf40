"""The camera's transfer curve reaches the colour tie-break's signatures (trained views and
queries) and survives the index's byte form."""

from __future__ import annotations

import numpy as np
import pytest

from vision.recognition import ViewIndex
from vision.recognition.colour import colour_signature
from vision.recognition.index import view_colour


def _banded(level: int = 90) -> np.ndarray:
    img = np.full((80, 120, 3), level, np.uint8)
    img[:, 20:40] = (200, 60, 40)  # a red band
    img[:, 70:80] = (40, 70, 180)  # a blue one
    return img


def test_the_curve_changes_the_signature_and_is_checked():
    img, region = _banded(), np.ones((80, 120), np.uint8)
    srgb = colour_signature(img, region)
    assert np.array_equal(srgb, colour_signature(img, region, transfer="srgb"))  # the default
    linear = colour_signature(img, region, transfer="linear")
    assert srgb is not None and linear is not None and not np.allclose(srgb, linear)
    with pytest.raises(ValueError, match="transfer must be one of linear, srgb, got 'gamma'"):
        colour_signature(img, region, transfer="gamma")
    outline = np.array([[0, 0], [119, 0], [119, 79], [0, 79]], np.float32)
    assert np.array_equal(view_colour(img, outline, transfer="linear"), linear)


def test_the_index_keeps_its_curve_for_views_and_in_bytes():
    with pytest.raises(ValueError, match="colour_transfer must be 'srgb' or 'linear'"):
        ViewIndex(colour_transfer="log")
    index = ViewIndex(method="orb", max_features=200, colour_transfer="linear")
    rng = np.random.default_rng(3)
    img = _banded()
    img[5:75, 45:65] = rng.integers(0, 255, (70, 20, 3), dtype=np.uint8)  # texture for ORB
    vid = index.add("twin", img, viewpoint=2)
    again = ViewIndex.from_bytes(index.to_bytes())
    assert again.colour_transfer == "linear"
    assert np.array_equal(again.view(vid).colour, index.view(vid).colour)
    outline = index.view(vid).outline
    assert np.array_equal(index.view(vid).colour, view_colour(img, outline, transfer="linear"))
