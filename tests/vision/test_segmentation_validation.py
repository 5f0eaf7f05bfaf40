"""Bad input to the segmentation functions: typed errors that name the parameter and value."""

import numpy as np
import pytest

from vision.errors import ImageError
from vision.segmentation import active_contour, blob_contour, chan_vese, circle_contour

GOOD = np.zeros((40, 50), np.uint8)
GOOD[10:30, 15:35] = 200
INIT = circle_contour((25, 20), 15.0, 40)


@pytest.mark.parametrize("fn", ["snake", "levelset"])
@pytest.mark.parametrize(
    ("image", "match"),
    [
        (
            np.zeros((40, 50), np.int32),
            "must be uint8, uint16, float32 or float64, got dtype int32",
        ),
        (np.zeros((40, 50), bool), "got dtype bool"),
        (np.zeros((40, 50), np.complex64), "got dtype complex64"),
        (
            np.zeros((40, 50, 4), np.uint8),
            r"must have shape \(H, W\) or \(H, W, 3\), got \(40, 50, 4\)",
        ),
        (np.zeros(40, np.uint8), r"got \(40,\)"),
        (np.zeros((2, 40, 50, 3), np.uint8), r"got \(2, 40, 50, 3\)"),
        (np.zeros((0, 50), np.uint8), r"is empty: shape \(0, 50\)"),
        (np.zeros((5, 50), np.uint8), "too small: 5x50 pixels, need at least 8"),
        (np.full((40, 50), np.nan), "contains NaN or infinity"),
        (np.full((40, 50), np.inf, np.float32), "contains NaN or infinity"),
        (np.full((40, 50), 2.0), r"must lie in \[0, 1\], got values in \[2.0, 2.0\]"),
        ([[0, 1], [1, 0]], "must be a numpy array, got list"),
    ],
)
def test_bad_images_raise_image_error(fn, image, match):
    with pytest.raises(ImageError, match=match) as info:
        if fn == "snake":
            active_contour(image, INIT)
        else:
            chan_vese(image, None)
    assert isinstance(info.value, ValueError)  # ImageError is a ValueError


def test_contour_outside_the_image():
    bad = INIT + np.array([40.0, 0.0])
    with pytest.raises(
        ValueError, match=r"init has \d+ point\(s\) outside the 50x40 image .* e\.g\. row \d+"
    ):
        active_contour(GOOD, bad)
    with pytest.raises(ValueError, match="outside the 50x40 image"):
        chan_vese(GOOD, bad)


@pytest.mark.parametrize(
    ("init", "match"),
    [
        (np.zeros((3, 2)), "init needs at least 5 points, got 3"),
        (np.zeros((10, 3)), r"init must have shape \(N, 2\) of \(x, y\) points, got \(10, 3\)"),
        (np.full((10, 2), np.nan), "init contains NaN or infinity, e.g. row 0"),
    ],
)
def test_bad_contours(init, match):
    with pytest.raises(ValueError, match=match):
        active_contour(GOOD, init)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"gamma": 0.0}, "gamma must be a positive number, got 0.0"),
        ({"gamma": -1}, "gamma must be a positive number, got -1"),
        ({"sigma_px": 0}, "sigma_px must be a positive number, got 0"),
        ({"lam": -2.0}, "lam must be a positive number, got -2.0"),
        ({"eps": 0.0}, "eps must be a positive number, got 0.0"),
        ({"alpha": -0.1}, "alpha must be a number >= 0, got -0.1"),
        ({"beta": float("nan")}, "beta must be a number >= 0, got nan"),
        ({"max_num_iter": 0}, "max_num_iter must be an integer >= 1, got 0"),
        ({"max_num_iter": 2.5}, "max_num_iter must be an integer >= 1, got 2.5"),
        ({"max_px_move": 0}, "max_px_move must be a positive number, got 0"),
        ({"n_points": 4}, "n_points must be an integer >= 5, got 4"),
        ({"resample_every": 0}, "resample_every must be an integer >= 1, got 0"),
        ({"balloon": float("inf")}, "balloon must be a finite number, got inf"),
        ({"external": "magic"}, "external must be 'edge' or 'gvf', got 'magic'"),
        ({"pyramid_levels": 4}, "pyramid_levels=4 is too many for a 40x50 image"),
        ({"pyramid_levels": -1}, "pyramid_levels must be an integer >= 0, got -1"),
        ({"snapshot_at": [-3]}, "snapshot_at must be an integer >= 0, got -3"),
        ({"roi_margin_px": -5.0}, "roi_margin_px must be a number >= 0, got -5.0"),
    ],
)
def test_snake_bad_parameters(kwargs, match):
    with pytest.raises(ValueError, match=match):
        active_contour(GOOD, INIT, **kwargs)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"mu": 0.0}, "mu must be a positive number, got 0.0"),
        ({"lambda1": -1.0}, "lambda1 must be a positive number, got -1.0"),
        ({"lambda2": 0}, "lambda2 must be a positive number, got 0"),
        ({"method": "fast"}, "method must be 'threshold' or 'pde', got 'fast'"),
        ({"sigma_px": -1}, "sigma_px must be a positive number, got -1"),
        ({"band_px": 0}, "band_px must be an integer >= 1, got 0"),
        ({"max_num_iter": 0}, "max_num_iter must be an integer >= 1, got 0"),
        ({"tol_px": -1}, "tol_px must be an integer >= 0, got -1"),
        ({"step_px": 0.0}, "step_px must be a positive number, got 0.0"),
    ],
)
def test_levelset_bad_parameters(kwargs, match):
    with pytest.raises(ValueError, match=match):
        chan_vese(GOOD, INIT, **kwargs)


def test_levelset_bad_init():
    with pytest.raises(
        ValueError,
        match=r"init must be a \(40, 50\) mask or an \(N, 2\) contour, got shape \(4, 4\)",
    ):
        chan_vese(GOOD, np.zeros((4, 4), bool))
    with pytest.raises(ValueError, match="init must leave pixels both inside and outside"):
        chan_vese(GOOD, np.ones((40, 50), bool))
    with pytest.raises(ValueError, match="init mask must be boolean or 0/1"):
        chan_vese(GOOD, np.full((40, 50), 7, np.uint8))


def test_blob_contour_on_a_constant_image():
    with pytest.raises(ImageError, match="image is constant"):
        blob_contour(np.full((40, 50), 9, np.uint8))
    with pytest.raises(ValueError, match="polarity must be 'auto', 'bright' or 'dark', got 'up'"):
        blob_contour(GOOD, polarity="up")
