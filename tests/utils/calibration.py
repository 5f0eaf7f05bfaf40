"""Synthetic calibration data with known truth: camera, board, robot poses, corners, images."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from vision.calibration import Chessboard, Detection
from vision.calibration.synthetic import BoardRenderer
from vision.calibration.views import candidate_camera_poses, plan_views
from vision.camera import PinholeCamera

#: A VGA camera with a moderately distorting lens (values of a typical 6 mm lens).
TRUE_CAMERA = PinholeCamera(
    [[610.0, 0.0, 318.5], [0.0, 612.0, 243.0], [0.0, 0.0, 1.0]],
    [-0.28, 0.11, 0.0008, -0.0004, 0.0],
    width=640,
    height=480,
)
BOARD = Chessboard(9, 6, 0.03)


def pose(
    rotvec_deg: tuple[float, float, float], t_m: tuple[float, float, float]
) -> NDArray[np.float64]:
    """4x4 pose from a rotation vector in degrees and a translation in metres."""
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(np.radians(rotvec_deg)).as_matrix()
    T[:3, 3] = t_m
    return T


#: Truth: the camera 60 mm ahead of the flange and 40 mm to the side, turned a little.
TRUE_T_EE_CAM = pose((2.0, -3.0, 91.0), (0.04, -0.015, 0.06))
#: Truth: the board on the table in front of the robot.
TRUE_T_BASE_BOARD = pose((180.0, 0.0, 30.0), (0.75, 0.1, 0.02))


@dataclass(frozen=True)
class HandEyeData:
    """Synthetic eye-in-hand samples with their truth."""

    T_base_ee: NDArray[np.float64]
    T_cam_board: NDArray[np.float64]
    detections: list[Detection]
    camera: PinholeCamera
    board: Chessboard


def hand_eye_samples(
    n: int = 15,
    *,
    noise_px: float = 0.15,
    seed: int = 1,
    camera: PinholeCamera = TRUE_CAMERA,
    board: Chessboard = BOARD,
    T_ee_cam: NDArray[np.float64] = TRUE_T_EE_CAM,
    T_base_board: NDArray[np.float64] = TRUE_T_BASE_BOARD,
) -> HandEyeData:
    """``n`` diverse views of the board (planned by ``plan_views``), the robot poses that
    produce them, and the corners projected by ``camera`` with Gaussian noise."""
    rng = np.random.default_rng(seed)
    cands = candidate_camera_poses(T_base_board, board, n=200, rng=rng)
    plan = plan_views(T_base_board, board, camera, cands, n_views=n)
    T_base_cam = plan.T_base_cam
    T_base_ee = T_base_cam @ np.linalg.inv(T_ee_cam)
    T_cam_board = np.linalg.inv(T_base_cam) @ T_base_board
    obj = board.object_points()
    dets = []
    for T in T_cam_board:
        uv = camera.project_world(obj, T) + rng.normal(0.0, noise_px, (obj.shape[0], 2))
        dets.append(
            Detection(True, uv, np.arange(obj.shape[0]), (camera.width, camera.height), "sb", "")
        )
    return HandEyeData(T_base_ee, T_cam_board, dets, camera, board)


def rendered_views(
    T_cam_board: NDArray[np.float64],
    *,
    camera: PinholeCamera = TRUE_CAMERA,
    board: Chessboard = BOARD,
    seed: int = 0,
) -> list[NDArray[np.uint8]]:
    """Greyscale images of the board at each pose."""
    renderer = BoardRenderer(board, camera)
    rng = np.random.default_rng(seed)
    return [renderer.render(T, rng=rng) for T in T_cam_board]


def rotation_error_deg(A: NDArray[np.float64], B: NDArray[np.float64]) -> float:
    """Angle of ``A^-1 B`` in degrees."""
    return float(np.degrees(Rotation.from_matrix(A[:3, :3].T @ B[:3, :3]).magnitude()))


def translation_error_mm(A: NDArray[np.float64], B: NDArray[np.float64]) -> float:
    """Distance between the translations, millimetres."""
    return float(np.linalg.norm(A[:3, 3] - B[:3, 3]) * 1e3)


@dataclass(frozen=True)
class SyntheticFolder:
    """Rendered board images written as PNG files, with the robot poses that took them."""

    folder: Path
    files: list[Path]
    poses_file: Path
    data: HandEyeData


def write_synthetic_folder(
    folder: Path, n: int = 8, *, seed: int = 4, blank: int = 1
) -> SyntheticFolder:
    """``n`` rendered views of :data:`BOARD` (plus ``blank`` images without a board, last)
    as ``view_XX.png`` in ``folder``, and ``poses.txt`` with one row-major 4x4
    ``T_base_ee`` per image (the blank images get the first pose again)."""
    import cv2

    folder.mkdir(parents=True, exist_ok=True)
    data = hand_eye_samples(n, seed=seed)
    images = rendered_views(data.T_cam_board, seed=seed)
    images += [np.full((TRUE_CAMERA.height, TRUE_CAMERA.width), 128, np.uint8)] * blank
    files = []
    for k, img in enumerate(images):
        path = folder / f"view_{k:02d}.png"
        cv2.imwrite(str(path), img)
        files.append(path)
    poses = list(data.T_base_ee) + [data.T_base_ee[0]] * blank
    poses_file = folder / "poses.txt"
    poses_file.write_text("\n".join(" ".join(f"{v:.12g}" for v in T.ravel()) for T in poses) + "\n")
    return SyntheticFolder(folder, files, poses_file, data)
