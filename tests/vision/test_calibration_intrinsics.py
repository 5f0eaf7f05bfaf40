"""Intrinsic calibration: OpenCV's real chessboard photos, and rendered views with known truth."""

import cv2
import numpy as np
import pytest

from tests.utils.calibration import TRUE_CAMERA, hand_eye_samples, rendered_views
from tests.vision.conftest import OPENCV_LEFT_BOARD
from vision.calibration import (
    Detection,
    IntrinsicsOptions,
    IntrinsicsResult,
    calibrate_intrinsics,
    calibrate_intrinsics_from_detections,
)
from vision.calibration.io import list_images, read_gray, read_intrinsics
from vision.errors import CalibrationError

REFERENCE_F = 535.9  # OpenCV's reference calibration of these images (left_intrinsics.yml)


@pytest.fixture(scope="module")
def left(opencv_left):
    return calibrate_intrinsics_from_detections(
        opencv_left.detections, OPENCV_LEFT_BOARD, names=opencv_left.names
    )


def test_opencv_left_meets_the_targets(left, opencv_left):
    ref = read_intrinsics(opencv_left.folder / "left_intrinsics.yml")
    assert ref.fx == pytest.approx(REFERENCE_F, abs=0.05)
    assert left.rms_px <= 0.25
    assert abs(left.K[0, 0] / REFERENCE_F - 1) <= 0.01
    assert abs(left.K[1, 1] / REFERENCE_F - 1) <= 0.01
    assert len(left.views) == 13 and left.rejected == ()
    assert left.image_size == (640, 480)
    assert left.dist[4] == 0.0  # k3 held (the chapter's two radial terms)
    assert np.all(np.isfinite(left.std_K)) and np.all(left.std_K > 0) and np.all(left.std_K < 2)
    assert left.std_dist[4] == 0.0 and np.all(left.std_dist[:4] > 0)
    per_view = np.array([v.rms_px for v in left.views])
    assert np.sqrt(np.sum(per_view**2 * 54) / (13 * 54)) == pytest.approx(left.rms_px, rel=1e-6)


def test_opencv_left_beats_the_classic_detector_baseline(left, opencv_left):
    """The data README: findChessboardCorners + cornerSubPix gives 0.41 px here."""
    obj, img = [], []
    for f in list_images(opencv_left.folder):
        g = read_gray(f)
        ok, c = cv2.findChessboardCorners(g, (9, 6), None)
        assert ok
        c = cv2.cornerSubPix(
            g,
            c,
            (11, 11),
            (-1, -1),
            (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001),
        )
        obj.append(OPENCV_LEFT_BOARD.object_points().astype(np.float32))
        img.append(c)
    rms = cv2.calibrateCamera(obj, img, (640, 480), None, None)[0]
    assert rms > 0.38 and left.rms_px < rms - 0.15


@pytest.mark.parametrize(
    ("options", "check"),
    [
        (IntrinsicsOptions(radial_only=True), lambda r: r.dist[2] == r.dist[3] == 0.0),
        (IntrinsicsOptions(k3=True), lambda r: r.dist[4] != 0.0 and r.std_dist[4] > 0),
        (IntrinsicsOptions(fix_aspect_ratio=True), lambda r: r.K[0, 0] == r.K[1, 1]),
    ],
)
def test_model_options(opencv_left, options, check):
    r = calibrate_intrinsics_from_detections(
        opencv_left.detections, OPENCV_LEFT_BOARD, options=options
    )
    assert check(r) and r.options == options
    assert r.rms_px < 0.27 and abs(r.K[0, 0] / REFERENCE_F - 1) < 0.01


def test_an_outlier_image_is_dropped_and_the_rest_solved_again(opencv_left, left):
    dets = list(opencv_left.detections)
    bad = dets[3]
    rng = np.random.default_rng(0)
    noisy = bad.image_points + rng.normal(0.0, 2.5, bad.image_points.shape)
    dets[3] = Detection(True, noisy, bad.ids, bad.image_size, bad.method, "")
    r = calibrate_intrinsics_from_detections(dets, OPENCV_LEFT_BOARD, names=opencv_left.names)
    assert [x.index for x in r.rejected] == [3]
    assert r.rejected[0].name == "left04.jpg"
    assert r.rejected[0].reason.startswith("outlier: reprojection RMS ")
    assert r.rms_px == pytest.approx(
        calibrate_intrinsics_from_detections(
            [d for i, d in enumerate(opencv_left.detections) if i != 3], OPENCV_LEFT_BOARD
        ).rms_px,
        rel=1e-9,
    )
    kept = calibrate_intrinsics_from_detections(
        dets, OPENCV_LEFT_BOARD, options=IntrinsicsOptions(reject_outliers=False)
    )
    assert kept.rejected == () and kept.rms_px > 0.6


def test_images_without_the_board_are_rejected_with_the_reason(opencv_left):
    dets = [*opencv_left.detections, Detection.missing((640, 480), "no 9x6 chessboard found")]
    r = calibrate_intrinsics_from_detections(
        dets, OPENCV_LEFT_BOARD, names=[*opencv_left.names, "blank.png"]
    )
    assert [(x.name, x.reason) for x in r.rejected] == [("blank.png", "no 9x6 chessboard found")]
    assert len(r.views) == 13


def test_too_few_views_is_a_clear_error(opencv_left):
    dets = [*opencv_left.detections[:3], Detection.missing((640, 480), "no 9x6 chessboard found")]
    names = ["a.png", "b.png", "c.png", "d.png"]
    with pytest.raises(
        CalibrationError,
        match=r"need at least 4 views with the board, got 3 of 4 \(rejected: d.png: no 9x6 chessboard found\)",
    ):
        calibrate_intrinsics_from_detections(dets, OPENCV_LEFT_BOARD, names=names)
    with pytest.raises(CalibrationError, match="no images to calibrate from"):
        calibrate_intrinsics_from_detections([], OPENCV_LEFT_BOARD)


def test_images_of_different_sizes_are_refused(opencv_left):
    d = opencv_left.detections[0]
    other = Detection(True, d.image_points, d.ids, (800, 600), "sb", "")
    with pytest.raises(CalibrationError, match="must have the same size, got 640x480, 800x600"):
        calibrate_intrinsics_from_detections([*opencv_left.detections, other], OPENCV_LEFT_BOARD)


def test_result_survives_json(left):
    back = IntrinsicsResult.from_dict(left.as_dict())
    assert back.as_dict() == left.as_dict()
    np.testing.assert_array_equal(back.K, left.K)
    assert back.camera.fx == left.K[0, 0]


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"outlier_factor": 1.0}, "outlier_factor must be > 1, got 1.0"),
        ({"min_views": 2}, "min_views must be an integer >= 3, got 2"),
    ],
)
def test_bad_options(kwargs, message):
    with pytest.raises(ValueError, match=message):
        IntrinsicsOptions(**kwargs)
    with pytest.raises(ValueError, match="unknown intrinsics options: bogus"):
        IntrinsicsOptions.from_dict({"bogus": 1})


def test_rendered_views_recover_the_true_camera():
    """Rendered views of a board through a known lens (``BoardRenderer``), detected and
    calibrated.  The simulator's ground-truth targets are asserted in
    ``tests/backend/test_calibration_sim_truth.py``; this keeps a fast check of the
    synthetic renderer that needs no simulator."""
    data = hand_eye_samples(15, seed=1)
    images = rendered_views(data.T_cam_board, seed=1)
    progress = []
    r = calibrate_intrinsics(images, data.board, progress=lambda f, m: progress.append(f))
    Kt = TRUE_CAMERA.K
    assert abs(r.K[0, 0] / Kt[0, 0] - 1) < 0.002 and abs(r.K[1, 1] / Kt[1, 1] - 1) < 0.002
    assert np.hypot(*(r.K[:2, 2] - Kt[:2, 2])) < 1.0
    np.testing.assert_allclose(r.dist[:2], TRUE_CAMERA.dist[:2], atol=0.01)
    assert r.rms_px < 0.1
    assert progress == sorted(progress) and progress[-1] == 1.0
