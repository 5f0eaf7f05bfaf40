"""Active contour (eqs. 6-11): convergence on known shapes, the maths, options."""

import numpy as np
import pytest
from segmentation_utils import distance_to_ellipse, ellipse_image

from vision.segmentation import (
    SnakeResult,
    active_contour,
    blob_contour,
    box_contour,
    circle_contour,
    internal_energy,
    internal_matrix,
    iou,
)
from vision.segmentation.snake import _factors

CENTER, AXES = (120.0, 100.0), (60.0, 40.0)


@pytest.fixture(scope="module")
def noisy_ellipse():
    return ellipse_image(center=CENTER, axes=AXES, noise=0.08, seed=1)


def test_snake_converges_onto_noisy_ellipse_within_one_pixel(noisy_ellipse):
    img, truth = noisy_ellipse
    res = active_contour(img, circle_contour(CENTER, 80.0, 150), balloon=-0.6)
    assert isinstance(res, SnakeResult) and res.converged
    err = distance_to_ellipse(res.contour, CENTER, AXES)
    assert err.mean() < 1.0, f"mean boundary error {err.mean():.3f} px"
    assert iou(res.mask, truth) > 0.97
    assert res.contour.shape == (150, 2) and res.mask.shape == truth.shape
    # (x, y) convention: x spans the wider axis of this ellipse.
    assert np.ptp(res.contour[:, 0]) > np.ptp(res.contour[:, 1])


def test_energy_of_eq8_decreases(noisy_ellipse):
    img, _ = noisy_ellipse
    res = active_contour(img, circle_contour(CENTER, 80.0, 150), balloon=-0.6)
    assert res.energy_iterations[0] == 0 and res.energy_iterations[-1] == res.iterations
    assert res.energy[-1] < 0.5 * res.energy[0]


def test_uint8_and_float_images_agree(noisy_ellipse):
    img, _ = noisy_ellipse
    a = active_contour(img, circle_contour(CENTER, 80.0, 120), balloon=-0.6)
    b = active_contour(
        np.round(img * 255).astype(np.uint8), circle_contour(CENTER, 80.0, 120), balloon=-0.6
    )
    assert iou(a.mask, b.mask) > 0.98


def test_box_and_otsu_blob_initialisations(noisy_ellipse):
    img, _ = noisy_ellipse
    box = box_contour(40, 45, 200, 155, n_points=160)
    res = active_contour(img, box, balloon=-0.6)
    assert distance_to_ellipse(res.contour, CENTER, AXES).mean() < 1.0
    blob = blob_contour((img * 255).astype(np.uint8), n_points=120, sigma_px=2.0)
    res2 = active_contour(img, blob)  # starts on the boundary: eq. 11 alone locks on
    assert distance_to_ellipse(res2.contour, CENTER, AXES).mean() < 1.0


def test_pure_eq11_snake_locks_onto_a_nearby_clean_edge():
    img, _ = ellipse_image(center=CENTER, axes=AXES, noise=0.0)
    init = np.stack(
        [
            CENTER[0] + 63 * np.cos(t := np.linspace(0, 2 * np.pi, 120, endpoint=False)),
            CENTER[1] + 43 * np.sin(t),
        ],
        axis=1,
    )
    res = active_contour(img, init, balloon=0.0, alpha=0.01, beta=1.0)
    assert distance_to_ellipse(res.contour, CENTER, AXES).mean() < 0.7


def test_gvf_captures_from_inside():
    # GVF points towards the edge from both sides: a circle inside grows onto it.
    img, _ = ellipse_image(center=CENTER, axes=AXES, noise=0.02)
    res = active_contour(
        img,
        circle_contour(CENTER, 30.0, 120),
        external="gvf",
        gvf_iterations=400,
        alpha=0.05,
        beta=1.0,
        max_num_iter=800,
        roi_margin_px=None,
    )
    assert distance_to_ellipse(res.contour, CENTER, AXES).mean() < 1.5


def test_isoluminant_colour_edge_is_found():
    # Red disc on green of (nearly) equal luminance: a grey edge map would be almost flat.
    h, w = 160, 160
    yy, xx = np.mgrid[:h, :w]
    inside = (xx - 80) ** 2 + (yy - 80) ** 2 < 40**2
    rgb = np.zeros((h, w, 3), np.uint8)
    rgb[inside] = (200, 60, 60)
    rgb[~inside] = (70, 120, 60)
    res = active_contour(rgb, circle_contour((80, 80), 60.0, 120), balloon=-0.6)
    r = np.hypot(res.contour[:, 0] - 80, res.contour[:, 1] - 80)
    assert abs(r.mean() - 40) < 1.0


def test_pyramid_on_a_large_image():
    img, truth = ellipse_image((600, 640), center=(320, 300), axes=(180, 120), noise=0.05)
    init = circle_contour((320, 300), 250.0, 200)
    res = active_contour(img, init, balloon=-0.6, pyramid_levels=2)
    assert res.converged
    assert distance_to_ellipse(res.contour, (320, 300), (180, 120)).mean() < 1.0
    assert iou(res.mask, truth) > 0.98


def test_snapshots_and_progress(noisy_ellipse):
    img, _ = noisy_ellipse
    calls = []
    res = active_contour(
        img,
        circle_contour(CENTER, 80.0, 100),
        balloon=-0.6,
        snapshot_at=(0, 5, 20, 10_000),
        progress=lambda f, m: calls.append(f),
    )
    its = [i for i, _ in res.snapshots]
    assert its == [0, 5, 20]
    np.testing.assert_allclose(res.snapshots[0][1], circle_contour(CENTER, 80.0, 100))
    assert not np.allclose(res.snapshots[1][1], res.snapshots[2][1])
    assert calls[-1] == 1.0 and all(0.0 <= f <= 1.0 for f in calls)


def test_roi_does_not_change_the_result(noisy_ellipse):
    img, _ = noisy_ellipse
    a = active_contour(img, circle_contour(CENTER, 80.0, 120), balloon=-0.6)
    b = active_contour(img, circle_contour(CENTER, 80.0, 120), balloon=-0.6, roi_margin_px=None)
    assert iou(a.mask, b.mask) > 0.97


def test_internal_matrix_is_the_gradient_of_eq9():
    rng = np.random.default_rng(3)
    x = rng.normal(size=(9, 2))
    alpha, beta = 0.7, 1.9
    A = internal_matrix(9, alpha, beta)
    grad = np.zeros_like(x)
    h = 1e-6
    for i in range(9):
        for k in range(2):
            d = np.zeros_like(x)
            d[i, k] = h
            grad[i, k] = (
                internal_energy(x + d, alpha, beta) - internal_energy(x - d, alpha, beta)
            ) / (2 * h)
    np.testing.assert_allclose(A @ x, grad, atol=1e-6)
    np.testing.assert_allclose(A, A.T)
    assert np.allclose(A.sum(axis=1), 0.0)  # translations cost nothing


@pytest.mark.parametrize(
    ("n", "alpha", "beta", "gamma"),
    [(5, 0.1, 1, 1), (6, 0, 0, 2), (200, 0.3, 5, 1), (101, 0.01, 10, 0.5)],
)
def test_cyclic_banded_solve_matches_dense(n, alpha, beta, gamma):
    from vision.segmentation import _kernels

    factors = _factors(n, alpha, beta, gamma)
    M = internal_matrix(n, alpha, beta) + gamma * np.eye(n)
    r = np.random.default_rng(n).normal(size=n)
    out = np.empty(n)
    _kernels.solve_cyclic(*factors, r, out)
    np.testing.assert_allclose(out, np.linalg.solve(M, r), atol=1e-12)


def test_warm_up_runs_every_kernel():
    from vision.segmentation import warm_up

    assert warm_up() > 0.0


def test_auto_levels_and_pyramid_limits():
    from vision.segmentation import auto_levels, gaussian_pyramid

    assert auto_levels((100, 120)) == 0
    assert auto_levels((512, 512)) == 1
    assert auto_levels((1536, 2048)) == 3
    levels = gaussian_pyramid(np.zeros((100, 130), np.float32), 2)
    assert [lv.shape for lv in levels] == [(100, 130), (50, 65), (25, 33)]
    with pytest.raises(ValueError, match="pyramid_levels=4 is too many for a 100x130 image"):
        gaussian_pyramid(np.zeros((100, 130), np.float32), 4)
