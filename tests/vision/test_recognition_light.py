"""vision.recognition.light: the belt's colour round an object, the per-channel gain back to
the teach light, and what it gives recognition under a colour cast and a dimmed light."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from vision.errors import InvalidInput
from vision.recognition import ViewIndex, recognise
from vision.recognition.light import (
    GAIN_DEADBAND,
    MAX_GAIN,
    LightChanged,
    apply_gain,
    light_gain,
    surround_colour,
)

BELT = (92.0, 96.0, 104.0)  # a grey-blue belt, 8-bit linear values


#: High-contrast patches (a textured part) and low-contrast ones of several hues round the
#: part's grey (a plain part: a dimmer light or a cast takes its features below the
#: detector's threshold or changes their grey contrast).
TEXTURED = [(200, 60, 40), (40, 90, 230), (70, 160, 60), (170, 150, 140), (30, 40, 60)]
PLAIN = [(150, 100, 90), (90, 120, 170), (100, 150, 100)]


def _scene(
    seed: int = 3, size: int = 240, colours: list[tuple[int, int, int]] = TEXTURED
) -> tuple[np.ndarray, np.ndarray]:
    """An RGB part (patches of ``colours`` on grey 120) on a belt, and its mask."""
    rng = np.random.default_rng(seed)
    img = np.empty((size, size, 3), np.float64)
    img[:] = BELT
    img += rng.normal(0.0, 1.5, img.shape)  # the belt's texture and the sensor's noise
    mask = np.zeros((size, size), np.uint8)
    cv2.rectangle(mask, (50, 50), (190, 190), 1, -1)
    part = np.zeros_like(img)
    for _ in range(60):
        c = tuple(int(v) for v in rng.integers(52, 188, 2))
        col = colours[int(rng.integers(len(colours)))]
        axes = tuple(int(v) for v in rng.integers(4, 16, 2))
        cv2.ellipse(part, c, axes, float(rng.uniform(0, 180)), 0, 360, col, -1)
    inside = mask.astype(bool)
    img[inside] = np.where(part[inside] > 0, part[inside], (120, 120, 120))
    img = cv2.GaussianBlur(img, (3, 3), 0.8)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8), mask


def _lit(img: np.ndarray, gain: tuple[float, float, float]) -> np.ndarray:
    """The scene under another light: each channel scaled (the diagonal model), rounded."""
    return np.clip(np.rint(img.astype(np.float64) * np.array(gain)), 0, 255).astype(np.uint8)


def test_surround_colour_is_the_belt_not_the_part():
    img, mask = _scene()
    belt = surround_colour(img, mask)
    assert belt is not None
    np.testing.assert_allclose(belt, BELT, atol=1.0)
    # Clipped pixels round the part (a reflection) say nothing of the light: left out.
    img2 = img.copy()
    img2[:40, :] = 255
    np.testing.assert_allclose(surround_colour(img2, mask), BELT, atol=1.0)


def test_surround_colour_none_without_colour_mask_or_belt():
    img, mask = _scene()
    assert surround_colour(img[..., 0], mask) is None  # grey
    assert surround_colour(img, None) is None
    full = np.ones(mask.shape, np.uint8)
    assert surround_colour(img, full) is None  # no belt left round the part
    with pytest.raises(InvalidInput, match="mask"):
        surround_colour(img, mask[:10])
    with pytest.raises(InvalidInput, match="8-bit"):
        surround_colour(img.astype(np.float32), mask)


def test_light_gain_recovers_a_diagonal_light_change():
    img, mask = _scene()
    cast = (1.0, 0.85, 0.6)
    ref = surround_colour(img, mask)
    now = surround_colour(_lit(img, cast), mask)
    g = light_gain(ref, now)
    assert g is not None
    np.testing.assert_allclose(g, 1.0 / np.array(cast), rtol=0.02)
    # The same light: no correction (every channel within the dead band).
    assert light_gain(ref, ref * (1.0 + GAIN_DEADBAND / 2)) is None
    assert light_gain(None, now) is None and light_gain(ref, None) is None


def test_light_gain_refuses_what_a_gain_cannot_undo_and_bad_colours():
    ref = np.array(BELT)
    with pytest.raises(LightChanged, match="gain"):
        light_gain(ref, ref / (MAX_GAIN * 1.5))
    for bad in (np.array([1.0, np.nan, 2.0]), np.array([1.0, 0.0, 2.0]), np.array([1.0, 2.0])):
        with pytest.raises(InvalidInput, match="belt colour"):
            light_gain(ref, bad)


def test_apply_gain_scales_each_channel_and_leaves_none_alone():
    img, _ = _scene()
    assert apply_gain(img, None) is img
    g = np.array([1.0, 1.0 / 0.85, 1.0 / 0.6])
    out = apply_gain(_lit(img, (1.0, 0.85, 0.6)), g)
    assert out.dtype == np.uint8 and out.shape == img.shape
    # Back to the taught light within the rounding of the cast (at most 1 / 0.6 levels).
    assert np.abs(out.astype(int) - img.astype(int)).max() <= 2
    with pytest.raises(InvalidInput, match="gain"):
        apply_gain(img, np.array([1.0, np.inf, 1.0]))
    with pytest.raises(InvalidInput, match="8-bit RGB"):
        apply_gain(img[..., 0], g)


@pytest.mark.parametrize("light", [(1.0, 0.85, 0.6), (0.45, 0.45, 0.45)], ids=["cast", "dim"])
def test_balanced_query_scores_as_under_the_teach_light(light):
    """A plain part taught under white light, seen turned under a cast or dimmed: the
    balanced query scores (nearly) as the query under the teach light, the query as seen
    far lower (in this scene 0.37 and 0.36 against 0.73)."""
    img, mask = _scene(colours=PLAIN)
    other, _ = _scene(seed=11, colours=PLAIN)
    index = ViewIndex("sift")
    index.add("part", img, mask=mask)
    index.add("other", other, mask=mask)
    query = cv2.warpAffine(img, cv2.getRotationMatrix2D((120, 120), 17.0, 1.0), (240, 240),
                           borderMode=cv2.BORDER_REPLICATE)  # fmt: skip
    qmask = cv2.warpAffine(mask, cv2.getRotationMatrix2D((120, 120), 17.0, 1.0), (240, 240),
                           flags=cv2.INTER_NEAREST)  # fmt: skip
    seen = _lit(query, light)
    gain = light_gain(surround_colour(img, mask), surround_colour(seen, qmask))
    assert gain is not None
    same = recognise(index, query, mask=qmask).scores["part"]
    as_seen = recognise(index, seen, mask=qmask).scores["part"]
    balanced = recognise(index, apply_gain(seen, gain), mask=qmask).scores["part"]
    assert balanced > as_seen + 0.15, (same, as_seen, balanced)
    assert balanced >= 0.85 * same, (same, as_seen, balanced)
