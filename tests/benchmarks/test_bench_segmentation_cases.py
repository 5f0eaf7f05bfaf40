"""The segmentation benchmark's image providers: rendered wheels, and skipping a provider."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks import segmentation_cases as sc
from benchmarks.segmentation_sim import WHEELS


@pytest.mark.slow
def test_sim_provider_renders_wheels_with_masks_inside_their_initial_ellipses():
    cases, skipped = sc.all_cases(["sim"])
    assert skipped == {}
    assert len(cases) == len(WHEELS) >= 4
    for case in cases:
        assert case.provider == "sim"
        assert case.image.shape == (480, 640, 3) and case.image.dtype == np.uint8
        assert case.reference.shape == (480, 640) and case.reference.dtype == bool
        assert 20_000 < case.reference.sum() < 0.5 * case.reference.size
        x0, y0, x1, y1 = sc.roi_box(case.init, case.image.shape, margin_px=0)
        ys, xs = np.nonzero(case.reference)
        assert x0 < xs.min() and xs.max() < x1 and y0 < ys.min() and ys.max() < y1
        # The wheel differs from its surroundings in the image (a real render, not blank).
        grey = case.image.mean(axis=2)
        assert grey[case.reference].std() > 5.0
    # Five different wheel types: five different images.
    assert len({c.image.tobytes() for c in cases}) == len(cases)


def test_unavailable_provider_is_skipped_with_its_reason(monkeypatch):
    def broken() -> list[sc.Case]:
        raise sc.ProviderUnavailable("MuJoCo rendering failed: no EGL display")

    monkeypatch.setitem(sc.PROVIDERS, "sim", broken)
    monkeypatch.setitem(sc.PROVIDERS, "skimage", lambda: [])
    cases, skipped = sc.all_cases()
    assert cases == []
    assert skipped == {"sim": "MuJoCo rendering failed: no EGL display"}


def test_unknown_provider_is_refused():
    with pytest.raises(ValueError, match="unknown provider"):
        sc.all_cases(["skimage", "bogus"])
