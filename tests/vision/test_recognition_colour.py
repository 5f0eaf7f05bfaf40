"""vision.recognition.colour (signatures, similarity, regions), the colour kept with a trained
view (and through the byte form), and the twins' colour tie-break of recognise_views
(issue 14): two models with the same grey images, one with a red band."""

from __future__ import annotations

import asyncio

import cv2
import numpy as np
import pytest

from tests.vision.recognition_utils import noise, textured
from vision.recognition import ViewIndex, recognise_views
from vision.recognition.colour import (
    SIGNATURE_SIZE,
    check_signature,
    colour_distance,
    colour_signature,
    region_from_outline,
)
from vision.recognition.index import view_colour


def _rgb(grey: np.ndarray) -> np.ndarray:
    return np.repeat(grey[:, :, None], 3, axis=2)


def _banded(grey: np.ndarray, rows: slice) -> np.ndarray:
    """RGB of ``grey`` with the pixels of ``rows`` turned red at the same BT.601 grey level,
    so that the grey image (what the features see) stays the same within rounding."""
    rgb = _rgb(grey).astype(np.float64)
    y = grey[rows].astype(np.float64)
    r = np.clip(1.8 * y, 0, 255)
    gb = np.clip((y - 0.299 * r) / 0.701, 0, 255)
    rgb[rows, :, 0], rgb[rows, :, 1], rgb[rows, :, 2] = r, gb, gb
    return np.round(rgb).astype(np.uint8)


def test_signature_sums_to_one_and_sees_a_small_band() -> None:
    grey = np.full((100, 100), 120, np.uint8)
    region = np.ones((100, 100), np.uint8)
    plain = colour_signature(_rgb(grey), region)
    band = colour_signature(_banded(grey, slice(0, 3)), region)  # 3 % of the region
    assert plain is not None and band is not None
    assert plain.shape == band.shape == (SIGNATURE_SIZE,)
    assert plain.sum() == pytest.approx(1.0) and band.sum() == pytest.approx(1.0)
    assert plain[0] == pytest.approx(1.0)  # all achromatic
    assert band[0] == pytest.approx(0.97, abs=0.005)  # 3 % moved out of the grey share
    assert colour_distance(band, band) == 0.0
    # No red against 3 % red.  Pure red (hue angle 0) lies midway between the centres of
    # two sectors, so its share is split 1.5 % / 1.5 % (interpolated votes):
    # 2 log(0.017 / 0.002).
    assert band[4] == pytest.approx(0.015, abs=0.002) and band[5] == pytest.approx(0.015, abs=0.002)
    assert colour_distance(plain, band) == pytest.approx(2 * np.log(0.017 / 0.002), abs=0.1)
    # Twice the grey around the same band: log 2 per sector it covers (here two), far less
    # than no band at all.
    wide = np.hstack([_banded(grey, slice(0, 3)), _rgb(grey)])  # the band on half the width
    wider = colour_signature(wide, np.ones((100, 200), np.uint8))
    assert wider is not None
    assert colour_distance(band, wider) < 1.5 < colour_distance(plain, wider) - 1.0


def test_signature_is_unchanged_by_the_light_intensity() -> None:
    rng = np.random.default_rng(3)
    rgb = rng.integers(60, 200, (80, 80, 3)).astype(np.uint8)
    region = np.ones((80, 80), np.uint8)
    # Half the linear light: the sRGB curve applied to half the linear values.
    from vision.features.colour_input import srgb_decode, srgb_encode

    darker = np.round(255 * srgb_encode(0.5 * srgb_decode(rgb / 255.0))).astype(np.uint8)
    a, b = colour_signature(rgb, region), colour_signature(darker, region)
    assert a is not None and b is not None
    assert colour_distance(a, b) < 0.3


def test_signature_needs_enough_usable_pixels() -> None:
    rgb = np.full((50, 50, 3), 128, np.uint8)
    small = np.zeros((50, 50), np.uint8)
    small[:10, :10] = 1  # 100 px < MIN_PIXELS
    assert colour_signature(rgb, small) is None
    black = np.zeros((50, 50, 3), np.uint8)  # too dark everywhere
    assert colour_signature(black, np.ones((50, 50), np.uint8)) is None


@pytest.mark.parametrize(
    ("image", "region", "match"),
    [
        (np.zeros((20, 20), np.uint8), np.ones((20, 20)), "RGB"),
        (np.zeros((20, 20, 3), np.float32), np.ones((20, 20)), "uint8"),
        (np.zeros((20, 20, 3), np.uint8), np.ones((10, 20)), "region shape"),
    ],
)
def test_signature_rejects_bad_input(image: np.ndarray, region: np.ndarray, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        colour_signature(image, region)


@pytest.mark.parametrize(
    "bad",
    [np.zeros(SIGNATURE_SIZE - 1), np.full(SIGNATURE_SIZE, np.nan), -np.eye(SIGNATURE_SIZE)[0]],
)
def test_check_signature_rejects(bad: np.ndarray) -> None:
    with pytest.raises(ValueError, match="colour signature"):
        check_signature(bad)


def test_region_from_outline_maps_by_H() -> None:
    pts = np.array([[10, 10], [30, 10], [30, 30], [10, 30], [20, 20]], float)
    H = np.array([[1, 0, 40], [0, 1, 5], [0, 0, 1]], float)
    r = region_from_outline(pts, (60, 80), H)
    ys, xs = np.nonzero(r)
    assert (xs.min(), xs.max(), ys.min(), ys.max()) == (50, 70, 15, 35)
    assert not region_from_outline(pts[:2], (60, 80)).any()  # too few points: no region
    with pytest.raises(ValueError, match="3x3"):
        region_from_outline(pts, (60, 80), np.eye(2))


def test_trained_view_keeps_its_colour_through_bytes() -> None:
    ix = ViewIndex("sift")
    grey = textured(0)
    v_rgb = ix.add("red", _banded(grey, slice(20, 40)), viewpoint=2)
    v_grey = ix.add("grey", grey, viewpoint=2)
    assert ix.view(v_rgb).colour is not None and ix.view(v_grey).colour is None
    back = ViewIndex.from_bytes(ix.to_bytes())
    np.testing.assert_array_equal(back.view(v_rgb).colour, ix.view(v_rgb).colour)
    np.testing.assert_array_equal(back.view(v_rgb).outline, ix.view(v_rgb).outline)
    assert back.view(v_grey).colour is None and back.view(v_grey).outline is None
    # Views given as features take their colour explicitly (as the database stores them).
    sig = ix.view(v_rgb).colour
    v3 = back.add("red", ix.view(v_rgb).features, viewpoint=3, colour=sig)
    np.testing.assert_array_equal(back.view(v3).colour, sig)
    with pytest.raises(ValueError, match="colour signature"):
        back.add("red", ix.view(v_rgb).features, viewpoint=3, colour=np.ones(3))
    with pytest.raises(ValueError, match="outline"):
        back.add("red", ix.view(v_rgb).features, viewpoint=3, colour=sig, outline=np.ones(5))


def test_outline_is_the_masks_hull() -> None:
    """The colour region of a masked view is the whole masked object (a band at its edge,
    where no keypoint lies, is inside), not the hull of the keypoints."""
    ix = ViewIndex("sift")
    mask = np.zeros((160, 160), np.uint8)
    mask[10:150, 20:140] = 1
    vid = ix.add("m", _rgb(textured(0)), viewpoint=2, mask=mask)
    out = ix.view(vid).outline
    assert out is not None
    assert out[:, 0].min() == 20 and out[:, 0].max() == 139
    assert out[:, 1].min() == 10 and out[:, 1].max() == 149


# ---------------------------------------------------------------- the twins' tie-break
BAND = slice(60, 75)  # rows of the red band on the side views of "banded"


@pytest.fixture(scope="module")
def twins() -> ViewIndex:
    """``plain`` and ``banded``: the same grey top and side views; ``banded``'s side views
    carry a red band at the same grey level. ``other`` is a distinct model."""
    ix = ViewIndex("sift")
    for m in ("plain", "banded"):
        ix.add(m, _rgb(textured(0)), viewpoint=1)
    ix.add("other", _rgb(textured(5)), viewpoint=1)
    for vp, seed in ((2, 10), (3, 11)):
        ix.add("plain", _rgb(textured(seed)), viewpoint=vp)
        ix.add("banded", _banded(textured(seed), BAND), viewpoint=vp)
        ix.add("other", _rgb(textured(seed + 20)), viewpoint=vp)
    return ix


def _shift(img: np.ndarray, dx: int, dy: int) -> np.ndarray:
    M = np.array([[1, 0, dx], [0, 1, dy]], np.float32)
    return cv2.warpAffine(img, M, img.shape[1::-1], borderMode=cv2.BORDER_REPLICATE)


def _look(model: str | None):
    def look(vp: int) -> np.ndarray:
        if model is None:
            return _rgb(noise(200 + vp))
        if vp == 1:
            return _shift(_rgb(textured(0)), 3, 2)
        grey = textured(10 if vp == 2 else 11)
        img = _banded(grey, BAND) if model == "banded" else _rgb(grey)
        return _shift(img, 3, 2)

    return look


@pytest.mark.parametrize("model", ["plain", "banded"])
def test_colour_names_the_twin(twins: ViewIndex, model: str) -> None:
    r = asyncio.run(recognise_views(_look(model), twins, policy="two-views", threshold=0.1))
    assert r.viewpoints[0] == 1 and len(r.viewpoints) >= 2
    # Geometrically the twins tie on the side views ...
    side = r.views[1].scores
    assert side["banded"] == pytest.approx(side["plain"], rel=0.2)
    # ... and the colour of the side view names the right one.
    assert (r.decision, r.model) == ("recognized", model)


def test_grey_query_leaves_the_twins_ambiguous(twins: ViewIndex) -> None:
    """Without colour in the query there is nothing to break the tie with."""

    def look(vp: int) -> np.ndarray:
        return cv2.cvtColor(_look("banded")(vp), cv2.COLOR_RGB2GRAY)

    r = asyncio.run(recognise_views(look, twins, policy="two-views", threshold=0.1))
    assert r.decision == "ambiguous" and set(r.contenders) == {"plain", "banded"}


def test_colour_does_not_name_an_unknown_object(twins: ViewIndex) -> None:
    r = asyncio.run(recognise_views(_look(None), twins, policy="two-views", threshold=0.1))
    assert r.decision == "unknown" and r.model is None


def test_view_colour_of_a_query_uses_the_mapped_outline(twins: ViewIndex) -> None:
    view = twins.views_of("banded", viewpoint=2)[0]
    query = _shift(_banded(textured(10), BAND), 3, 2)
    H = np.array([[1, 0, 3], [0, 1, 2], [0, 0, 1]], float)
    assert view.outline is not None and view.colour is not None
    q = view_colour(query, view.outline, H=H)
    assert q is not None
    assert colour_distance(q, view.colour) < 0.2
    assert view_colour(cv2.cvtColor(query, cv2.COLOR_RGB2GRAY), view.outline, H=H) is None
