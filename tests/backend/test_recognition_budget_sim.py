"""Short version of ``benchmarks/recognition_budget.py``: the valve block (a plain top face,
55-75 features per taught view) and a wheel taught from the top in the simulated cell, then
put back at seeded random yaws up to 20 mm along the belt, each top view recognised with the
verification budget and with the two best-voted views per model (the rule before).

The budget verifies the same best-voted views first, then more of a model's views while
their features fit: the own model's score can only rise, more views are verified for the
plain part, and no fewer for the wheel."""

from __future__ import annotations

import pytest

from benchmarks.recognition_budget import run

pytestmark = pytest.mark.slow


def test_the_budget_verifies_more_views_of_a_plain_part_and_never_scores_lower():
    out = run(names=["valve-block", "wheel-steel"], untrained=["oil-filter"], queries=3,
              teach_yaws=3, seed=4)  # fmt: skip
    budget, votes = out["rules"]["budget"]["rows"], out["rules"]["by votes"]["rows"]
    assert len(budget) == len(votes) == 9
    for b, v in zip(budget, votes, strict=True):
        assert b["name"] == v["name"]
        assert b["own"] >= v["own"] - 1e-9, (b, v)
        assert b["verified"] >= v["verified"], (b, v)
    valve = [(b["verified"], v["verified"]) for b, v in zip(budget, votes, strict=True)
             if b["name"] == "valve-block"]  # fmt: skip
    assert all(nb > nv for nb, nv in valve), valve
    assert all(r["own"] > 0.0 for r in budget if r["name"] == "valve-block"), budget
