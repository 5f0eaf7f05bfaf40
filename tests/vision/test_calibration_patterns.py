"""Board detection on rendered images with known corner positions, and on real photos."""

import numpy as np
import pytest

from tests.utils.calibration import BOARD, TRUE_CAMERA, pose
from vision.calibration import CharucoBoard, Chessboard, detect_pattern
from vision.calibration import patterns as patterns_module
from vision.calibration.synthetic import BoardRenderer
from vision.camera import PinholeCamera
from vision.errors import ImageError

T_VIEW = pose((18.0, -14.0, 8.0), (-0.12, -0.08, 0.5))


@pytest.fixture(scope="module")
def renderer():
    return BoardRenderer(BOARD, TRUE_CAMERA)


@pytest.fixture(scope="module")
def image(renderer):
    return renderer.render(T_VIEW, rng=np.random.default_rng(3))


def _errors(det, truth):
    return np.linalg.norm(det.image_points - truth[det.ids], axis=1)


def test_chessboard_corners_are_found_to_a_tenth_of_a_pixel(renderer, image):
    det = detect_pattern(image, BOARD)
    assert det.found and det.method == "sb" and det.reason == ""
    assert det.n_points == 54 and det.image_size == (640, 480)
    err = _errors(det, renderer.corners(T_VIEW))
    assert err.mean() < 0.08 and err.max() < 0.25


def test_rgb_input_gives_the_same_corners(image):
    rgb = np.repeat(image[:, :, None], 3, axis=2)
    np.testing.assert_allclose(
        detect_pattern(rgb, BOARD).image_points, detect_pattern(image, BOARD).image_points
    )


@pytest.mark.parametrize("turn", [1, 2, 3])
def test_corner_order_follows_the_board_not_the_image(renderer, image, turn):
    """Turning the image by 90, 180 or 270 degrees must give the same physical corners in
    the same order: the board frame (hand-eye depends on it) is fixed by the squares."""
    turned = np.ascontiguousarray(np.rot90(image, turn))
    det = detect_pattern(turned, BOARD)
    assert det.found
    truth = renderer.corners(T_VIEW)
    h, w = image.shape
    for _ in range(turn):  # np.rot90 turns counter-clockwise: (u, v) -> (v, W - 1 - u)
        truth = np.stack([truth[:, 1], w - 1 - truth[:, 0]], axis=1)
        h, w = w, h
    assert _errors(det, truth).max() < 0.3


def test_classic_detector_takes_over_when_the_sector_based_one_fails(monkeypatch, renderer, image):
    monkeypatch.setattr(patterns_module, "_find_sb", lambda *a, **k: None)
    det = detect_pattern(image, BOARD)
    assert det.found and det.method == "classic"
    assert _errors(det, renderer.corners(T_VIEW)).max() < 0.4


def test_padded_retry_maps_corners_back(monkeypatch, renderer, image):
    real = patterns_module._find_sb

    def fail_unpadded(gray, board, flags):
        return None if gray.shape == image.shape else real(gray, board, flags)

    monkeypatch.setattr(patterns_module, "_find_sb", fail_unpadded)
    det = detect_pattern(image, BOARD)
    assert det.method == "sb-padded"
    assert _errors(det, renderer.corners(T_VIEW)).max() < 0.25


def test_large_images_are_searched_small_and_located_at_full_resolution():
    cam = PinholeCamera(
        [[1500.0, 0, 959.5], [0, 1500.0, 599.5], [0, 0, 1]],
        [-0.12, 0.07, 0, 0, 0],
        width=1920,
        height=1200,
    )
    board = Chessboard(24, 17, 0.015)
    T = pose((12.0, 10.0, 3.0), (-0.17, -0.12, 0.55))
    ren = BoardRenderer(board, cam, supersample=1, px_per_square=24)
    det = detect_pattern(ren.render(T, blur_sigma_px=0.8), board, detect_max_side_px=960)
    assert det.found and det.method == "sb"
    err = np.linalg.norm(det.image_points - ren.corners(T), axis=1)
    assert err.mean() < 0.1 and err.max() < 0.35


def test_charuco_corners_and_ids():
    board = CharucoBoard(7, 5, 0.04, 0.03)
    ren = BoardRenderer(board, TRUE_CAMERA)
    T = pose((15.0, -20.0, 5.0), (-0.13, -0.08, 0.55))
    det = detect_pattern(ren.render(T), board)
    assert det.found and det.method == "charuco" and det.n_points == board.n_corners
    assert np.all(np.diff(det.ids) > 0)
    err = np.linalg.norm(det.image_points - ren.corners(T)[det.ids], axis=1)
    assert err.max() < 0.3


def test_partial_charuco_view_keeps_the_visible_corners():
    board = CharucoBoard(7, 5, 0.04, 0.03)
    ren = BoardRenderer(board, TRUE_CAMERA)
    T = pose((5.0, -5.0, 0.0), (-0.25, -0.08, 0.45))  # board runs off the left edge
    det = detect_pattern(ren.render(T), board)
    assert det.found and 6 <= det.n_points < board.n_corners
    assert np.linalg.norm(det.image_points - ren.corners(T)[det.ids], axis=1).max() < 0.3


def test_no_board_is_a_reason_not_an_error():
    det = detect_pattern(np.full((480, 640), 128, np.uint8), BOARD)
    assert not det.found and det.n_points == 0
    assert det.reason == "no 9x6 chessboard found (sector-based and classic detectors)"
    det = detect_pattern(np.full((480, 640), 128, np.uint8), CharucoBoard(7, 5, 0.04, 0.03))
    assert det.reason == "only 0 ChArUco corners found (0 markers), need at least 6"


@pytest.mark.parametrize(
    ("img", "message"),
    [
        (np.zeros((10, 10), np.float32), "image must be uint8, got dtype float32"),
        (
            np.zeros((10, 10, 4), np.uint8),
            r"image must have shape \(H, W\) or \(H, W, 3\), got \(10, 10, 4\)",
        ),
    ],
)
def test_bad_images_are_refused(img, message):
    with pytest.raises(ImageError, match=message):
        detect_pattern(img, BOARD)


def test_real_photos_are_all_found(opencv_left):
    assert all(d.found for d in opencv_left.detections)
    assert {d.method for d in opencv_left.detections} == {"sb"}
