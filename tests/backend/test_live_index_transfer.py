"""The live index takes the settings' transfer curve: an option of the colour descriptor's
extraction (so part of its descriptor version) and the tie-break's reading of colours."""

from __future__ import annotations

import pytest

from backend.recognition.index import LiveIndex
from backend.settings import Settings


def test_colour_method_extracts_with_the_curve_and_versions_it():
    linear = LiveIndex(method="color-sift", max_features=50, transfer=("linear", "linear"))
    srgb = LiveIndex(method="color-sift", max_features=50, transfer=("srgb", "srgb"))
    with linear.reading() as a, srgb.reading() as b:
        assert "transfer" not in a.feature_options and b.feature_options["transfer"] == "srgb"
        assert (a.colour_transfer, b.colour_transfer) == ("linear", "srgb")
    # Views extracted with the other curve are stale under this one.
    assert srgb.version == linear.version + ";srgb" and len(srgb.version) <= 32


def test_grey_methods_ignore_the_descriptor_curve_and_the_settings_reach_it():
    a = LiveIndex(method="orb", max_features=50, transfer=("srgb", "linear"))
    b = LiveIndex(method="orb", max_features=50)
    assert a.version == b.version
    with a.reading() as index:
        assert index.colour_transfer == "linear"
    s = Settings(camera="folder", camera_transfer="srgb")
    live = LiveIndex(method="orb", max_features=50, transfer=s.resolved_camera_transfer())
    with live.reading() as index:
        assert index.colour_transfer == "srgb"
    with pytest.raises(ValueError, match="transfer must be 'linear' or 'srgb'"):
        LiveIndex(method="orb", transfer=("gamma", "srgb"))
