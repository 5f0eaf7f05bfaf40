"""Camera and hand-eye calibration (chapter sections 3.1 and 3.3).

- :mod:`~vision.calibration.boards`: chessboard and ChArUco targets, ``"9x6"``/``"25mm"`` parsing.
- :mod:`~vision.calibration.patterns`: finding the board in an image.
- :mod:`~vision.calibration.intrinsics`: ``K`` and the lens distortion (eqs. 1-5).
- :mod:`~vision.calibration.handeye`: ``T_ee_cam`` of the eye-in-hand camera (eqs. 12-13).
- :mod:`~vision.calibration.coverage` and :mod:`~vision.calibration.views`: when a view set
  is good enough, and which views to take next.
- :mod:`~vision.calibration.report`: PNG plots; :mod:`~vision.calibration.synthetic`:
  rendered boards with known truth; :mod:`~vision.calibration.io`: reading image folders,
  robot pose files and intrinsics files.
"""

from vision.calibration.boards import (
    ARUCO_DICTIONARIES,
    MAX_BOARD_SIDE,
    MAX_SQUARE_M,
    MIN_SQUARE_M,
    Board,
    CharucoBoard,
    Chessboard,
    board_from_dict,
    parse_board_size,
    parse_length_m,
)
from vision.calibration.charuco_refine import refine_charuco_corners
from vision.calibration.coverage import (
    CoverageMap,
    RotationDiversity,
    ViewSetCriteria,
    coverage_map,
    rotation_diversity,
)
from vision.calibration.handeye import (
    ALL_METHODS,
    HAND_EYE_METHODS,
    ROBOT_WORLD_METHODS,
    HandEyeCandidate,
    HandEyeOptions,
    HandEyeResult,
    PoseResidual,
    board_pose,
    calibrate_hand_eye,
    check_poses,
    motion_warnings,
    solve_hand_eye,
)
from vision.calibration.intrinsics import (
    IntrinsicsOptions,
    IntrinsicsResult,
    RejectedView,
    ViewResidual,
    calibrate_intrinsics,
    calibrate_intrinsics_from_detections,
)
from vision.calibration.patterns import Detection, detect_pattern, detect_patterns
from vision.calibration.views import ViewPlan, candidate_camera_poses, look_at, plan_views

__all__ = [
    "ALL_METHODS",
    "ARUCO_DICTIONARIES",
    "HAND_EYE_METHODS",
    "MAX_BOARD_SIDE",
    "MAX_SQUARE_M",
    "MIN_SQUARE_M",
    "ROBOT_WORLD_METHODS",
    "Board",
    "CharucoBoard",
    "Chessboard",
    "CoverageMap",
    "Detection",
    "HandEyeCandidate",
    "HandEyeOptions",
    "HandEyeResult",
    "IntrinsicsOptions",
    "IntrinsicsResult",
    "PoseResidual",
    "RejectedView",
    "RotationDiversity",
    "ViewPlan",
    "ViewResidual",
    "ViewSetCriteria",
    "board_from_dict",
    "board_pose",
    "calibrate_hand_eye",
    "calibrate_intrinsics",
    "calibrate_intrinsics_from_detections",
    "candidate_camera_poses",
    "check_poses",
    "coverage_map",
    "detect_pattern",
    "detect_patterns",
    "look_at",
    "motion_warnings",
    "parse_board_size",
    "parse_length_m",
    "plan_views",
    "refine_charuco_corners",
    "rotation_diversity",
    "solve_hand_eye",
]
