"""Real calibration data, detected once per test session (the 1920x1200 hand-eye images
take a while)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from vision.calibration import Chessboard, Detection, detect_pattern
from vision.calibration.io import list_images, read_gray, read_poses

OPENCV_LEFT_BOARD = Chessboard(9, 6, 0.025)
#: calib.io board "18x25 | Checker Size: 15 mm" printed on it: 25 x 18 squares, so 24 x 17
#: inner corners (found by detection; the data README gives only the square size).
KUKA_BOARD = Chessboard(24, 17, 0.015)


@dataclass(frozen=True)
class RealSet:
    folder: Path
    names: list[str]
    detections: list[Detection]
    poses: np.ndarray | None


def _folder(data_dir: Path, name: str) -> Path:
    folder = data_dir / "calibration" / name
    if not folder.is_dir():
        pytest.skip(f"{folder} is absent (see the data README)")
    return folder


@pytest.fixture(scope="session")
def opencv_left(data_dir) -> RealSet:
    folder = _folder(data_dir, "opencv-left")
    files = list_images(folder)
    dets = [detect_pattern(read_gray(f), OPENCV_LEFT_BOARD) for f in files]
    return RealSet(folder, [f.name for f in files], dets, None)


@pytest.fixture(scope="session")
def kuka(data_dir) -> RealSet:
    folder = _folder(data_dir, "handeye-kuka2")
    files = list_images(folder)
    dets = [detect_pattern(read_gray(f), KUKA_BOARD) for f in files]
    return RealSet(folder, [f.name for f in files], dets, read_poses(folder / "RobotPosesVec.txt"))
