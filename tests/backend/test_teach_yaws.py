"""The object yaws of a multi-round teach: spread over a half turn (backend.recognition.teach)."""

from __future__ import annotations

import math

import pytest

from backend.recognition.teach import MAX_ROUNDS, teach_yaws_rad
from vision.errors import InvalidInput


def _side_pairs(yaws):
    """The pairs of faces the two opposite side views see: a yaw modulo a half turn."""
    return {round(math.degrees(y) % 180.0, 6) for y in yaws}


@pytest.mark.parametrize("n", range(1, MAX_ROUNDS + 1))
def test_every_round_adds_a_pair_of_side_faces(n):
    yaws = teach_yaws_rad(n)
    assert len(yaws) == n and yaws[0] == 0.0
    assert all(0.0 <= y < math.pi for y in yaws)
    assert len(_side_pairs(yaws)) == n
    gaps = [b - a for a, b in zip(yaws, (*yaws[1:], yaws[0] + math.pi), strict=True)]
    assert max(gaps) == pytest.approx(min(gaps)) == pytest.approx(math.pi / n)


def test_four_rounds_are_0_45_90_135_degrees():
    assert [math.degrees(y) for y in teach_yaws_rad(4)] == pytest.approx([0, 45, 90, 135])
    full = [math.remainder(2 * math.pi * k / 4, 2 * math.pi) for k in range(4)]  # before
    assert len(_side_pairs(full)) == 2


@pytest.mark.parametrize("bad", [0, MAX_ROUNDS + 1, -1, 2.0, True, "4", None])
def test_bad_round_counts_are_refused(bad):
    with pytest.raises(InvalidInput, match="rounds"):
        teach_yaws_rad(bad)
