"""Chan-Vese level set: noisy synthetic images, colour, energy, snapshots, pyramid."""

import numpy as np
import pytest
from segmentation_utils import ellipse_image

from vision.segmentation import LevelSetResult, chan_vese, circle_contour, iou, mask_from_contour

CENTER, AXES = (120.0, 100.0), (60.0, 40.0)


@pytest.fixture(scope="module")
def noisy():
    # Noise std 0.15 on a contrast of 0.3: SNR 2, hard for edge-based methods.
    return ellipse_image(center=CENTER, axes=AXES, inside=0.6, outside=0.3, noise=0.15, seed=2)


@pytest.mark.parametrize("method", ["threshold", "pde"])
def test_noisy_synthetic_image(noisy, method):
    img, truth = noisy
    init = circle_contour(CENTER, 75.0, 100)
    res = chan_vese(img, init, method=method, max_num_iter=400)
    assert isinstance(res, LevelSetResult) and res.converged
    assert iou(res.mask, truth) > 0.95
    np.testing.assert_allclose(res.mean_inside, [0.6], atol=0.03)
    np.testing.assert_allclose(res.mean_outside, [0.3], atol=0.03)
    assert res.contour.shape[1] == 2 and res.contour.shape[0] > 100


def test_threshold_dynamics_energy_never_increases():
    # At a fixed diffusion scale (no continuation) every step minimises the linearised
    # energy, which cannot raise the energy (Esedoglu and Tsai 2006).
    img, _ = ellipse_image(center=CENTER, axes=AXES, noise=0.08, seed=3)
    for band in (None, 1):
        res = chan_vese(img, circle_contour(CENTER, 75.0, 100), band_px=band, sigma_start_px=3.0)
        assert res.converged and len(res.energy) > 3
        assert np.all(np.diff(res.energy) <= 1e-6 * abs(res.energy[0])), band


def test_global_evolution_is_faster_than_the_banded_one(noisy):
    img, truth = noisy
    init = circle_contour(CENTER, 75.0, 100)
    banded = chan_vese(img, init)
    free = chan_vese(img, init, band_px=None)
    assert free.iterations < banded.iterations
    assert iou(free.mask, truth) > 0.95


def test_colour_image_uses_all_channels():
    # Two colours of the same grey level: only the vector-valued model can tell them apart.
    h, w = 120, 140
    yy, xx = np.mgrid[:h, :w]
    truth = (xx - 70) ** 2 + (yy - 60) ** 2 < 30**2
    rgb = np.empty((h, w, 3), np.float32)
    rgb[truth] = (0.6, 0.3, 0.3)
    rgb[~truth] = (0.3, 0.45, 0.45)
    rng = np.random.default_rng(5)
    rgb = np.clip(rgb + rng.normal(0, 0.05, rgb.shape), 0, 1).astype(np.float32)
    init = circle_contour((70, 60), 45.0, 80)
    res = chan_vese(rgb, init)
    assert iou(res.mask, truth) > 0.95
    assert res.mean_inside.shape == (3,)
    grey = rgb.mean(axis=2)  # equal means: the grey image carries no region contrast
    assert iou(chan_vese(grey, init).mask, truth) < 0.8


def test_figure3_snapshots_show_the_evolution(noisy):
    img, _ = noisy
    res = chan_vese(
        img, circle_contour(CENTER, 75.0, 100), method="pde", snapshot_at=(0, 20, 50, 70)
    )
    its = [i for i, _ in res.snapshots]
    assert its == [0, 20, 50, 70]
    areas = []
    for _, contours in res.snapshots:
        assert len(contours) >= 1
        areas.append(mask_from_contour(max(contours, key=len), img.shape).sum())
    assert areas[0] > areas[1] > areas[2]  # the front shrinks from the loose initial circle


def test_pyramid_gives_the_same_region(noisy):
    img, truth = noisy
    init = circle_contour(CENTER, 75.0, 100)
    coarse = chan_vese(img, init, pyramid_levels=2)
    assert iou(coarse.mask, truth) > 0.94
    assert coarse.mask.shape == truth.shape


def test_init_forms(noisy):
    img, truth = noisy
    as_mask = chan_vese(img, mask_from_contour(circle_contour(CENTER, 75.0, 100), img.shape))
    as_contour = chan_vese(img, circle_contour(CENTER, 75.0, 100))
    assert iou(as_mask.mask, as_contour.mask) > 0.99
    default = chan_vese(img)  # centred disc
    assert iou(default.mask, truth) > 0.9


def test_progress_is_reported(noisy):
    img, _ = noisy
    seen = []
    chan_vese(img, circle_contour(CENTER, 75.0, 100), progress=lambda f, m: seen.append((f, m)))
    assert seen[-1][0] == 1.0 and all(0.0 <= f <= 1.0 for f, _ in seen)
    assert any("iteration" in m for _, m in seen)


# --- Localised region model (Lankton and Tannenbaum 2008) ---------------------------------


def _belt_crop(seed: int = 7):
    """A dark disc on a slightly lighter belt, bright strips at the crop's sides (the wheel
    case): the global two-phase contrast is strips against the rest, not disc against belt."""
    h, w = 140, 160
    yy, xx = np.mgrid[:h, :w]
    truth = (xx - 80) ** 2 + (yy - 70) ** 2 < 40**2
    img = np.full((h, w), 0.25, np.float32)
    img[truth] = 0.08
    img[:, :14] = 0.95
    img[:, -14:] = 0.95
    rng = np.random.default_rng(seed)
    return np.clip(img + rng.normal(0, 0.04, img.shape), 0, 1).astype(np.float32), truth


@pytest.mark.parametrize("method", ["threshold", "pde"])
def test_local_model_succeeds_where_the_global_one_fails(method):
    img, truth = _belt_crop()
    init = circle_contour((80, 70), 46.0, 100)
    glob = chan_vese(img, init, method=method)
    local = chan_vese(img, init, method=method, local_radius_px=8.0)
    assert iou(glob.mask, truth) < 0.8  # the belt goes in with the disc
    assert local.converged and iou(local.mask, truth) > 0.97


def test_local_model_on_a_colour_image():
    # The belt case in colour: reddish disc, cyan-tinted belt, white strips.
    img, truth = _belt_crop(seed=9)
    rgb = np.repeat(img[:, :, None], 3, axis=2)
    rgb[truth] += [0.2, -0.05, -0.05]
    rgb[~truth & (img < 0.6)] += [0.0, 0.05, 0.05]
    rgb = np.clip(rgb, 0, 1).astype(np.float32)
    init = circle_contour((80, 70), 46.0, 100)
    res = chan_vese(rgb, init, local_radius_px=8.0)
    assert iou(res.mask, truth) > 0.95


def test_local_radius_none_is_the_global_model(noisy):
    img, _ = noisy
    init = circle_contour(CENTER, 75.0, 100)
    for method in ("threshold", "pde"):
        default = chan_vese(img, init, method=method)
        explicit = chan_vese(img, init, method=method, local_radius_px=None)
        np.testing.assert_array_equal(default.mask, explicit.mask)
        np.testing.assert_array_equal(default.energy, explicit.energy)


def test_local_model_with_huge_window_matches_the_global_one():
    # A window much wider than the image holds the whole image (reflected borders): the local
    # means are the global ones.  Small image: the blur's cost grows with the window.
    yy, xx = np.mgrid[:48, :56]
    truth = (xx - 28) ** 2 + (yy - 24) ** 2 < 12**2
    rng = np.random.default_rng(4)
    img = np.clip(0.3 + 0.3 * truth + rng.normal(0, 0.08, truth.shape), 0, 1).astype(np.float32)
    init = circle_contour((28, 24), 18.0, 60)
    glob = chan_vese(img, init)
    local = chan_vese(img, init, local_radius_px=300.0)
    assert iou(glob.mask, local.mask) > 0.98 and iou(local.mask, truth) > 0.9


@pytest.mark.parametrize("bad", [0.0, -2.0, float("nan"), "wide"])
def test_local_radius_is_validated(noisy, bad):
    img, _ = noisy
    with pytest.raises(ValueError, match="local_radius_px"):
        chan_vese(img, local_radius_px=bad)
