"""Hand-eye calibration of the eye-in-hand camera (chapter section 3.3, eqs. 12-13).

The chapter's eq. 12, ``P_camera = H_ee^camera P_ee``, maps end-effector points to camera
points, so its ``H`` is ``T_cam_ee`` in our naming; we solve its inverse ``T_ee_cam``, the
pose of the camera in the flange frame, so that ``T_base_cam = T_base_ee @ T_ee_cam``.

Each sample pairs the robot's ``T_base_ee`` with the board pose ``T_cam_board`` that PnP
finds in the image.  The board is fixed in the cell, so for every sample

    T_base_board = T_base_ee_i @ T_ee_cam @ T_cam_board_i                       (*)

OpenCV's five ``AX = XB`` solvers (Tsai-Lenz, Park-Martin, Horaud-Dornaika,
Andreff-Horaud-Espiau, Daniilidis) and its two robot-world-hand-eye solvers (Shah, Li et al.)
give candidates; the one whose board poses (*) reproject the detected corners best is
refined by minimising that reprojection error over ``T_ee_cam`` and ``T_base_board``
together (12 parameters, ``scipy.optimize.least_squares``).  The report gives, per sample,
how far the board pose predicted by (*) lies from the solution's ``T_base_board`` in
millimetres and degrees; their spread is the consistency check.

References
----------
R. Tsai and R. Lenz, IEEE Trans. Robotics and Automation 5(3), 1989.
F. Park and B. Martin, IEEE Trans. Robotics and Automation 10(5), 1994.
R. Horaud and F. Dornaika, Int. J. Robotics Research 14(3), 1995.
N. Andreff, R. Horaud and B. Espiau, 3DIM 2001.
K. Daniilidis, Int. J. Robotics Research 18(3), 1999.
M. Shah, J. Mechanisms and Robotics 5(3), 2013.
A. Li, L. Wang and D. Wu, Int. J. Physical Sciences 5(10), 2010.
K. Koide and E. Menegatti, "General hand-eye calibration based on reprojection error
minimization", IEEE Robotics and Automation Letters 4(2), 2019 (the refinement).
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from vision.calibration.boards import Board
from vision.calibration.coverage import (
    RotationDiversity,
    coverage_map,
    rotation_diversity,
)
from vision.calibration.handeye_types import (
    ALL_METHODS,
    HandEyeCandidate,
    HandEyeOptions,
    HandEyeResult,
    PoseResidual,
)
from vision.calibration.intrinsics import RejectedView, pose_from_rvec
from vision.calibration.patterns import Detection, ProgressFn
from vision.camera import PinholeCamera
from vision.errors import CalibrationError

__all__ = [
    "ALL_METHODS",
    "HAND_EYE_METHODS",
    "ROBOT_WORLD_METHODS",
    "HandEyeCandidate",
    "HandEyeOptions",
    "HandEyeResult",
    "PoseResidual",
    "board_pose",
    "calibrate_hand_eye",
    "check_poses",
    "motion_warnings",
    "solve_hand_eye",
]

HAND_EYE_METHODS = {
    "tsai": cv2.CALIB_HAND_EYE_TSAI,
    "park": cv2.CALIB_HAND_EYE_PARK,
    "horaud": cv2.CALIB_HAND_EYE_HORAUD,
    "andreff": cv2.CALIB_HAND_EYE_ANDREFF,
    "daniilidis": cv2.CALIB_HAND_EYE_DANIILIDIS,
}
ROBOT_WORLD_METHODS = {
    "shah": cv2.CALIB_ROBOT_WORLD_HAND_EYE_SHAH,
    "li": cv2.CALIB_ROBOT_WORLD_HAND_EYE_LI,
}
assert (*HAND_EYE_METHODS, *ROBOT_WORLD_METHODS) == ALL_METHODS


def _T(R: ArrayLike, t: ArrayLike) -> NDArray[np.float64]:
    T = np.eye(4)
    T[:3, :3] = np.asarray(R, dtype=np.float64)
    T[:3, 3] = np.asarray(t, dtype=np.float64).ravel()
    return T


def _inv(T: NDArray[np.float64]) -> NDArray[np.float64]:
    R, t = T[..., :3, :3], T[..., :3, 3]
    out = np.zeros_like(T)
    out[..., :3, :3] = np.swapaxes(R, -1, -2)
    out[..., :3, 3] = -np.einsum("...ji,...j->...i", R, t)
    out[..., 3, 3] = 1.0
    return out


def check_poses(T: ArrayLike, name: str = "T_base_ee", *, tol: float = 1e-4) -> NDArray[np.float64]:
    """Validate rigid poses (N, 4, 4) and return them as float64 with rotations made exactly
    orthonormal (robot controllers print a few digits)."""
    P = np.asarray(T, dtype=np.float64)
    if P.ndim != 3 or P.shape[1:] != (4, 4):
        raise ValueError(f"{name} must have shape (N, 4, 4), got {P.shape}")
    if not np.all(np.isfinite(P)):
        bad = sorted({int(i) for i in np.argwhere(~np.isfinite(P))[:, 0]})
        raise ValueError(f"{name} contains NaN or infinity in poses {bad}")
    out = P.copy()
    for i, M in enumerate(P):
        if not np.allclose(M[3], [0.0, 0.0, 0.0, 1.0], atol=1e-9):
            raise ValueError(f"{name}[{i}] must have last row (0, 0, 0, 1), got {M[3].tolist()}")
        R = M[:3, :3]
        err = float(np.abs(R.T @ R - np.eye(3)).max())
        if err > tol or np.linalg.det(R) < 0:
            raise ValueError(
                f"{name}[{i}] has no rotation matrix in its top-left 3x3 "
                f"(|R^T R - I| = {err:.2g}, det = {np.linalg.det(R):.4f})"
            )
        u, _, vt = np.linalg.svd(R)
        out[i, :3, :3] = u @ vt
    return out


def board_pose(
    detection: Detection, board: Board, camera: PinholeCamera
) -> tuple[NDArray[np.float64], float]:
    """``T_cam_board`` of one detection by PnP (IPPE for the planar board, then
    Levenberg-Marquardt), with its reprojection RMS in pixels."""
    obj = detection.object_points(board)
    img = detection.image_points
    ok, rvec, tvec = cv2.solvePnP(obj, img, camera.K, camera.dist, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        raise CalibrationError("PnP found no board pose")
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, camera.K, camera.dist, rvec, tvec)
    T = pose_from_rvec(rvec, tvec)
    proj = camera.project_world(obj, T)
    return T, float(np.sqrt(np.mean(np.sum((proj - img) ** 2, axis=1))))


def solve_hand_eye(
    T_base_ee: ArrayLike, T_cam_board: ArrayLike, method: str = "park"
) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
    """One closed-form solution of ``T_ee_cam``.

    Returns ``(T_ee_cam, T_base_board)``; ``T_base_board`` is None for the ``AX = XB``
    methods (tsai, park, horaud, andreff, daniilidis) and solved jointly by the
    robot-world methods (shah, li).
    """
    A = check_poses(T_base_ee, "T_base_ee")
    B = check_poses(T_cam_board, "T_cam_board")
    if A.shape[0] != B.shape[0]:
        raise ValueError(
            f"T_base_ee and T_cam_board differ in length: {A.shape[0]} != {B.shape[0]}"
        )
    if method in HAND_EYE_METHODS:
        R, t = cv2.calibrateHandEye(
            list(A[:, :3, :3]),
            list(A[:, :3, 3]),
            list(B[:, :3, :3]),
            list(B[:, :3, 3]),
            method=HAND_EYE_METHODS[method],
        )
        return _T(R, t), None
    if method in ROBOT_WORLD_METHODS:
        # OpenCV's world is our board and its gripper our ee: inputs are world->cam
        # (T_cam_board) and base->gripper (T_ee_base); outputs base->world (T_board_base)
        # and gripper->cam (T_cam_ee).
        G = _inv(A)
        R_bw, t_bw, R_gc, t_gc = cv2.calibrateRobotWorldHandEye(
            list(B[:, :3, :3]),
            list(B[:, :3, 3]),
            list(G[:, :3, :3]),
            list(G[:, :3, 3]),
            method=ROBOT_WORLD_METHODS[method],
        )
        return _inv(_T(R_gc, t_gc)), _inv(_T(R_bw, t_bw))
    raise ValueError(f"method must be one of {', '.join(ALL_METHODS)}, got {method!r}")


def motion_warnings(diversity: RotationDiversity, options: HandEyeOptions) -> list[str]:
    """Check the robot motions (Tsai and Lenz's observations); raise on degenerate motion.

    Raises
    ------
    CalibrationError
        Pure translations, or rotations all about one axis: ``T_ee_cam`` is not determined.
    """
    o = options
    if diversity.max_angle_deg < o.degenerate_angle_deg:
        raise CalibrationError(
            f"degenerate motion: the robot orientations differ by at most "
            f"{diversity.max_angle_deg:.2f} deg (pure translations?); hand-eye calibration "
            f"needs rotations about at least two different axes"
        )
    if diversity.axis_spread_deg < o.degenerate_axis_deg:
        raise CalibrationError(
            f"degenerate motion: all robot rotations turn about one axis (axis spread "
            f"{diversity.axis_spread_deg:.2f} deg); hand-eye calibration needs rotations "
            f"about at least two different axes"
        )
    out = []
    if diversity.max_angle_deg < o.warn_angle_deg:
        out.append(
            f"weak motion: the largest rotation between poses is {diversity.max_angle_deg:.1f} "
            f"deg (aim for more than {o.warn_angle_deg:g} deg)"
        )
    if diversity.axis_spread_deg < o.warn_axis_deg:
        out.append(
            f"weak motion: the rotation axes spread over {diversity.axis_spread_deg:.1f} deg "
            f"(aim for more than {o.warn_axis_deg:g} deg; tilt the camera about different axes)"
        )
    return out


def _mean_pose(T: NDArray[np.float64]) -> NDArray[np.float64]:
    R = Rotation.from_matrix(T[:, :3, :3]).mean().as_matrix()
    return _T(R, T[:, :3, 3].mean(axis=0))


def _pose_errors(
    T: NDArray[np.float64], ref: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Offsets (N, 3) mm, distances (N,) mm and angles (N,) deg of poses T from ref."""
    off = (T[:, :3, 3] - ref[:3, 3]) * 1e3
    rel = np.einsum("ji,njk->nik", ref[:3, :3], T[:, :3, :3])
    ang = np.degrees(Rotation.from_matrix(rel).magnitude())
    return off, np.linalg.norm(off, axis=1), ang


class _Chain:
    """Reprojection of every sample's corners through (*) (vectorised over samples)."""

    def __init__(
        self,
        T_base_ee: NDArray[np.float64],
        obj: list[NDArray[np.float64]],
        img: list[NDArray[np.float64]],
        camera: PinholeCamera,
    ) -> None:
        self.T_ee_base = _inv(T_base_ee)
        self.counts = [o.shape[0] for o in obj]
        self.sample = np.repeat(np.arange(len(obj)), self.counts)
        self.obj = np.concatenate(obj)
        self.img = np.concatenate(img)
        self.camera = camera

    def residuals(self, X: NDArray[np.float64], B: NDArray[np.float64]) -> NDArray[np.float64]:
        # T_cam_board_i = X^-1 T_ee_base_i B for every sample i.
        T = np.einsum("ij,njk,kl->nil", _inv(X), self.T_ee_base, B)
        Ts = T[self.sample]
        p_cam = np.einsum("nij,nj->ni", Ts[:, :3, :3], self.obj) + Ts[:, :3, 3]
        return (self.camera.project(p_cam) - self.img).ravel()

    def per_sample_rms(self, X: NDArray[np.float64], B: NDArray[np.float64]) -> NDArray[np.float64]:
        r = self.residuals(X, B).reshape(-1, 2)
        sq = np.sum(r**2, axis=1)
        sums = np.bincount(self.sample, weights=sq, minlength=len(self.counts))
        return np.sqrt(sums / np.asarray(self.counts))

    def rms(self, X: NDArray[np.float64], B: NDArray[np.float64]) -> float:
        r = self.residuals(X, B).reshape(-1, 2)
        return float(np.sqrt(np.mean(np.sum(r**2, axis=1))))


def _refine(
    chain: _Chain, X0: NDArray[np.float64], B0: NDArray[np.float64], options: HandEyeOptions
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Minimise the reprojection error over X = T_ee_cam and B = T_base_board.

    Parameters are small rotation vectors applied on the right of the initial rotations
    (no singularity near the start) and the two translations, 12 in all.
    """
    RX0, RB0 = X0[:3, :3], B0[:3, :3]

    def unpack(p: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        X = _T(RX0 @ Rotation.from_rotvec(p[0:3]).as_matrix(), p[3:6])
        B = _T(RB0 @ Rotation.from_rotvec(p[6:9]).as_matrix(), p[9:12])
        return X, B

    p0 = np.concatenate([np.zeros(3), X0[:3, 3], np.zeros(3), B0[:3, 3]])
    sol = least_squares(
        lambda p: chain.residuals(*unpack(p)),
        p0,
        method="trf",
        loss=options.loss,
        f_scale=options.f_scale_px,
        x_scale="jac",
        xtol=1e-12,
        ftol=1e-12,
        gtol=1e-12,
        max_nfev=200,
    )
    return unpack(sol.x)


def calibrate_hand_eye(
    detections: Sequence[Detection],
    T_base_ee: ArrayLike,
    board: Board,
    camera: PinholeCamera,
    *,
    names: Sequence[str] | None = None,
    options: HandEyeOptions | None = None,
    progress: ProgressFn | None = None,
) -> HandEyeResult:
    """Solve ``T_ee_cam`` (the inverse of eq. 12's H) from board detections and robot poses.

    Parameters
    ----------
    detections : sequence of Detection
        The board in each sample's image (samples without it are rejected with the reason).
    T_base_ee : array of shape (N, 4, 4)
        The flange pose of each sample, metres.
    board : Chessboard or CharucoBoard
        The target; its frame must be unique (see ``Chessboard.orientation_unique``).
    camera : PinholeCamera
        Intrinsics of the camera (eqs. 1-5).
    names : sequence of str, optional
        Sample names for the report.
    options : HandEyeOptions, optional
        Solvers, refinement and thresholds.
    progress : callable, optional
        Called as ``progress(fraction, message)``.

    Raises
    ------
    CalibrationError
        Too few usable samples, or degenerate motion (pure translations, or rotations all
        about one axis).
    """
    opts = options or HandEyeOptions()
    if not board.orientation_unique:
        raise ValueError(
            f"board {board.describe()} has no unique frame (square pattern, or rows + cols "
            "even): hand-eye calibration needs one; use e.g. 9x6 or a ChArUco board"
        )
    A_all = check_poses(T_base_ee, "T_base_ee")
    n = len(detections)
    if A_all.shape[0] != n:
        raise ValueError(f"T_base_ee has {A_all.shape[0]} poses but there are {n} detections")
    labels = [f"pose {i}" for i in range(n)] if names is None else [str(s) for s in names]
    if len(labels) != n:
        raise ValueError(f"names must have one entry per sample ({n}), got {len(labels)}")

    def report(f: float, msg: str) -> None:
        if progress is not None:
            progress(f, msg)

    rejected: list[RejectedView] = []
    used: list[int] = []
    pnp: dict[int, tuple[NDArray[np.float64], float]] = {}
    for i, d in enumerate(detections):
        if not d.found:
            rejected.append(RejectedView(i, labels[i], d.reason or "pattern not found"))
        elif d.n_points < 6:
            rejected.append(RejectedView(i, labels[i], f"only {d.n_points} corners, need 6"))
        else:
            pnp[i] = board_pose(d, board, camera)
            used.append(i)
    if used:
        fits = np.array([pnp[i][1] for i in used])
        limit = max(opts.outlier_factor * float(np.median(fits)), opts.outlier_floor_px)
        for i in list(used):
            if pnp[i][1] > limit:
                used.remove(i)
                rejected.append(
                    RejectedView(
                        i,
                        labels[i],
                        f"board pose unreliable: PnP RMS {pnp[i][1]:.2f} px > {limit:.2f} px",
                    )
                )
    rejected.sort(key=lambda r: r.index)
    if len(used) < opts.min_poses:
        why = "; ".join(f"{r.name}: {r.reason}" for r in rejected) or "none"
        raise CalibrationError(
            f"need at least {opts.min_poses} samples with the board, got {len(used)} of {n} "
            f"(rejected: {why})"
        )
    A = A_all[used]
    Bc = np.array([pnp[i][0] for i in used])
    diversity = rotation_diversity(A)
    warnings = motion_warnings(diversity, opts)
    report(0.1, f"{len(used)} samples; trying {len(opts.methods)} solvers")

    chain = _Chain(
        A,
        [detections[i].object_points(board) for i in used],
        [detections[i].image_points for i in used],
        camera,
    )
    candidates: list[HandEyeCandidate] = []
    best: tuple[float, NDArray[np.float64], NDArray[np.float64], str] | None = None
    for k, method in enumerate(opts.methods):
        try:
            X, _ = solve_hand_eye(A, Bc, method)
        except cv2.error as exc:
            warnings.append(f"{method}: the solver failed ({exc.err})")
            continue
        if not np.all(np.isfinite(X)):
            warnings.append(f"{method}: the solver returned no finite answer")
            continue
        preds = np.einsum("nij,jk,nkl->nil", A, X, Bc)
        B = _mean_pose(preds)
        _, dist_mm, ang = _pose_errors(preds, B)
        rms = chain.rms(X, B)
        candidates.append(
            HandEyeCandidate(
                method,
                X,
                rms,
                float(np.sqrt(np.mean(dist_mm**2))),
                float(np.sqrt(np.mean(ang**2))),
            )
        )
        if np.isfinite(rms) and (best is None or rms < best[0]):
            best = (rms, X, B, method)
        report(0.1 + 0.5 * (k + 1) / len(opts.methods), f"{method}: {rms:.3f} px")
    if best is None:
        raise CalibrationError("every hand-eye solver failed: " + "; ".join(warnings))
    _, X, B, method = best
    if opts.refine:
        report(0.65, f"refining {method} by reprojection error")
        X, B = _refine(chain, X, B, opts)
    preds = np.einsum("nij,jk,nkl->nil", A, X, Bc)
    off, dist_mm, ang = _pose_errors(preds, B)
    rms_each = chain.per_sample_rms(X, B)
    poses = tuple(
        PoseResidual(
            i,
            labels[i],
            float(dist_mm[k]),
            float(ang[k]),
            (float(off[k, 0]), float(off[k, 1]), float(off[k, 2])),
            float(rms_each[k]),
            pnp[i][1],
        )
        for k, i in enumerate(used)
    )
    result = HandEyeResult(
        T_ee_cam=X,
        T_base_board=B,
        method=method,
        refined=opts.refine,
        rms_px=chain.rms(X, B),
        poses=poses,
        candidates=tuple(candidates),
        diversity=diversity,
        warnings=tuple(warnings),
        rejected=tuple(rejected),
        coverage=coverage_map(
            [detections[i].image_points for i in used], (camera.width, camera.height)
        ),
        K=camera.K.copy(),
        dist=camera.dist.copy(),
        options=opts,
    )
    report(
        1.0, f"T_ee_cam by {method}{' + refinement' if opts.refine else ''}: {result.rms_px:.3f} px"
    )
    return result
