"""Report pictures and the readers of pose and intrinsics files."""

import json

import cv2
import numpy as np
import pytest

from tests.utils.calibration import hand_eye_samples
from vision.calibration import calibrate_hand_eye, calibrate_intrinsics_from_detections
from vision.calibration.io import list_images, parse_poses, read_intrinsics, read_poses
from vision.calibration.report import consistency_png, coverage_png, residuals_png, summary_png


@pytest.fixture(scope="module")
def results():
    data = hand_eye_samples(10, seed=3)
    intr = calibrate_intrinsics_from_detections(data.detections, data.board)
    return intr, calibrate_hand_eye(data.detections, data.T_base_ee, data.board, intr.camera)


def _decode(png: bytes) -> np.ndarray:
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    img = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
    assert img is not None
    return img


def test_plots_are_pngs_with_content(results):
    intr, he = results
    for png in (
        residuals_png(intr),
        residuals_png(he),
        coverage_png(intr.coverage),
        consistency_png(he),
    ):
        img = _decode(png)
        assert img.shape[0] > 200 and img.shape[1] > 300 and img.std() > 10
    summary = summary_png(intr, he)
    assert len(summary) < 300_000 and _decode(summary).shape[1] > 800
    with pytest.raises(ValueError, match="result must be an IntrinsicsResult or a HandEyeResult"):
        residuals_png("nothing")


def test_poses_text_forms():
    T = np.array([[0, -1, 0, 0.5], [1, 0, 0, 0.2], [0, 0, 1, 0.3], [0, 0, 0, 1.0]])
    row16 = " ".join(str(v) for v in T.ravel())
    row12 = ",".join(str(v) for v in T[:3].ravel())
    P = parse_poses(f"# header\n{row16}\n\n{row12}  # comment\n")
    np.testing.assert_allclose(P, [T, T])
    mm = parse_poses(
        row16.replace("0.5", "500").replace("0.2", "200").replace("0.3", "300"), unit_m=1e-3
    )
    np.testing.assert_allclose(mm[0], T)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("1 2 3", "poses line 1: expected 16 numbers (a row-major 4x4 pose) or 12 (3x4), got 3"),
        ("# only a comment\n", "poses: no poses found"),
        ("1 2 x 4", "poses line 1: expected numbers, got '1 2 x 4'"),
    ],
)
def test_bad_poses_name_the_line(text, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")):
        parse_poses(text)


def test_real_pose_file(data_dir):
    folder = data_dir / "calibration" / "handeye-kuka2"
    P = read_poses(folder / "RobotPosesVec.txt")
    assert P.shape == (28, 4, 4) and len(list_images(folder)) == 28
    assert [p.name for p in list_images(folder)][:2] == ["im_01.png", "im_02.png"]


def test_intrinsics_files(tmp_path, results, data_dir):
    intr, _ = results
    j = tmp_path / "cam.json"
    j.write_text(json.dumps(intr.as_dict()))
    cam = read_intrinsics(j)
    np.testing.assert_allclose(cam.K, intr.K)
    assert (cam.width, cam.height) == intr.image_size
    yml = data_dir / "calibration" / "opencv-left" / "left_intrinsics.yml"
    ref = read_intrinsics(yml)
    assert ref.fx == pytest.approx(535.9157, abs=1e-3) and ref.dist[4] == pytest.approx(
        0.2384, abs=1e-4
    )
    bad = tmp_path / "bad.json"
    bad.write_text("{}")
    with pytest.raises(ValueError, match="is not a VisionCell intrinsics JSON"):
        read_intrinsics(bad)
    with pytest.raises(ValueError, match="intrinsics must be a file"):
        read_intrinsics(tmp_path / "missing.yml")
