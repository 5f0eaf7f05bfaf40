"""The object yaws of a multi-round teach (backend.recognition.teach.teach_yaws_rad)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from backend.recognition.teach import MAX_ROUNDS, teach_yaws_rad
from vision.errors import InvalidInput


@pytest.mark.parametrize("n", range(1, MAX_ROUNDS + 1))
def test_the_rounds_spread_evenly_over_the_whole_turn(n):
    yaws = teach_yaws_rad(n)
    assert len(yaws) == n and yaws[0] == 0.0
    assert all(-math.pi <= y <= math.pi for y in yaws)
    turns = sorted(y % (2 * math.pi) for y in yaws)
    gaps = np.diff([*turns, turns[0] + 2 * math.pi])
    assert gaps == pytest.approx([2 * math.pi / n] * n)


def test_four_rounds_are_0_90_180_and_minus_90_degrees():
    assert [math.degrees(y) for y in teach_yaws_rad(4)] == pytest.approx([0, 90, 180, -90])


@pytest.mark.parametrize("bad", [0, MAX_ROUNDS + 1, -1, 2.0, True, "4", None])
def test_bad_round_counts_are_refused(bad):
    with pytest.raises(InvalidInput, match="rounds"):
        teach_yaws_rad(bad)
