"""Contour helpers: initialisations, resampling, rasterisation, loop removal, IoU."""

import numpy as np
import pytest

from vision.segmentation import (
    _kernels,
    blob_contour,
    box_contour,
    circle_contour,
    contour_from_mask,
    ellipse_contour,
    iou,
    mask_from_contour,
    polygon_area,
    remove_loops,
    resample_closed,
)


def test_resample_closed_gives_equal_arc_lengths():
    square = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])
    r = resample_closed(square, 40)
    seg = np.hypot(*np.diff(np.vstack([r, r[:1]]), axis=0).T)
    np.testing.assert_allclose(seg, 1.0, atol=1e-12)
    # The compiled version the snake uses is the same function.
    np.testing.assert_allclose(_kernels.resample(square, 40), r, atol=1e-12)
    wobbly = circle_contour((5, 5), 4, 37) + np.random.default_rng(0).normal(0, 0.1, (37, 2))
    np.testing.assert_allclose(
        _kernels.resample(wobbly, 23), resample_closed(wobbly, 23), atol=1e-12
    )


@pytest.mark.parametrize("r", [3.3, 17.0, 60.5])
def test_mask_area_matches_polygon_area(r):
    c = circle_contour((70.3, 64.8), r, 300)
    m = mask_from_contour(c, (140, 150))
    assert abs(m.sum() - abs(polygon_area(c))) <= 2.0 * r**0.5 + 2.0


def test_mask_uses_pixel_centres_half_open():
    rect = np.array([[2.0, 2.0], [6.0, 2.0], [6.0, 5.0], [2.0, 5.0]])
    m = mask_from_contour(rect, (8, 8))
    assert m.sum() == 12 and m[2:5, 2:6].all()
    assert mask_from_contour(rect + 100, (8, 8)).sum() == 0  # entirely outside
    big = np.array([[-5.0, -5.0], [20.0, -5.0], [20.0, 20.0], [-5.0, 20.0]])
    assert mask_from_contour(big, (8, 8)).all()


def test_box_and_ellipse_contours():
    b = box_contour(1, 2, 11, 7, n_points=30)
    assert b.shape == (30, 2) and abs(abs(polygon_area(b)) - 50.0) < 1e-9
    e = ellipse_contour((0, 0), (4.0, 2.0), angle_deg=90.0, n_points=8)
    np.testing.assert_allclose(np.abs(e).max(axis=0), [2.0, 4.0], atol=1e-12)
    assert polygon_area(circle_contour((0, 0), 1.0, 50)) > 0  # clockwise on screen
    with pytest.raises(ValueError, match="box needs x1 > x0 and y1 > y0"):
        box_contour(5, 5, 1, 9)


def test_remove_loops_cuts_a_figure_eight_lobe():
    t = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    # A circle of radius 20 with a small knot that crosses itself.
    c = np.stack([50 + 20 * np.cos(t), 50 + 20 * np.sin(t)], axis=1)
    knot = np.array([[70.0, 50.0], [75.0, 47.0], [75.0, 53.0], [69.0, 49.0]])
    c = np.vstack([c[:1], knot, c[1:]])
    out = remove_loops(c)
    assert len(out) < len(c)
    assert _kernels.first_crossing(out)[0] == -1  # simple now
    assert abs(abs(polygon_area(out)) - np.pi * 400) < 20
    simple = circle_contour((0, 0), 5.0, 30)
    np.testing.assert_array_equal(remove_loops(simple), simple)


def test_contour_from_mask_and_iou():
    m = np.zeros((30, 40), bool)
    m[5:20, 10:30] = True
    m[25:27, 2:4] = True  # a smaller second region is ignored
    c = contour_from_mask(m)
    assert c[:, 0].min() == 10 and c[:, 0].max() == 29 and c[:, 1].max() == 19
    assert contour_from_mask(m, 50).shape == (50, 2)
    assert contour_from_mask(np.zeros((5, 5), bool)).shape == (0, 2)
    a = np.zeros((4, 4), bool)
    a[:2] = True
    b = np.zeros((4, 4), bool)
    b[1:3] = True
    assert iou(a, b) == pytest.approx(4 / 12)
    assert iou(np.zeros((3, 3), bool), np.zeros((3, 3), bool)) == 1.0
    with pytest.raises(ValueError, match=r"masks differ in shape: \(4, 4\) vs \(3, 3\)"):
        iou(a, np.zeros((3, 3), bool))


@pytest.mark.parametrize(("bright", "polarity"), [(True, "auto"), (False, "auto"), (False, "dark")])
def test_blob_contour_finds_the_otsu_blob(bright, polarity):
    yy, xx = np.mgrid[:100, :120]
    disc = (xx - 60) ** 2 + (yy - 50) ** 2 < 25**2
    img = np.where(disc, 200 if bright else 40, 40 if bright else 200).astype(np.uint8)
    rgb = np.dstack([img] * 3)
    c = blob_contour(rgb, n_points=64, polarity=polarity)
    assert c.shape == (64, 2)
    assert iou(mask_from_contour(c, img.shape), disc) > 0.95
