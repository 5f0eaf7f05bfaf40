"""Regression: the same detections solved in worker threads gave K differing in the last
bits (OpenCV's parallel sums), so a stored session did not re-solve to the same numbers."""

from concurrent.futures import ThreadPoolExecutor

from tests.utils.calibration import hand_eye_samples
from vision.calibration import calibrate_hand_eye, calibrate_intrinsics_from_detections


def test_solves_in_threads_are_bit_identical():
    d = hand_eye_samples(8, seed=4)
    with ThreadPoolExecutor(max_workers=3) as pool:
        intr = list(
            pool.map(
                lambda _: calibrate_intrinsics_from_detections(d.detections, d.board), range(6)
            )
        )
        he = list(
            pool.map(
                lambda _: calibrate_hand_eye(d.detections, d.T_base_ee, d.board, d.camera), range(3)
            )
        )
    assert all(r.as_dict() == intr[0].as_dict() for r in intr)
    assert all(r.as_dict() == he[0].as_dict() for r in he)
