"""Intrinsic camera calibration with the chapter's lens model (section 3.1, eqs. 1-5).

Zhang's method as implemented by OpenCV's ``calibrateCameraExtended`` estimates ``K``
(eq. 2) and the distortion ``(k1, k2, p1, p2[, k3])`` (eqs. 3-5) with a Levenberg-Marquardt
refinement of the reprojection error.  By default k3 is held at zero (the chapter's two
radial terms); ``radial_only`` also holds p1 = p2 = 0, the chapter's recommendation for
stability.  Views whose reprojection error stands out are dropped one at a time and the
problem is solved again; the standard deviations of the parameters come from the
Jacobian at the solution.

References
----------
Z. Zhang, "A flexible new technique for camera calibration", IEEE TPAMI 22(11), 2000.
R. Y. Tsai, "A versatile camera calibration technique...", IEEE J. Robotics and Automation
3(4), 1987 (few radial terms for stability, cited by the chapter).
"""

from __future__ import annotations

import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from vision.calibration.boards import Board, board_from_dict
from vision.calibration.coverage import (
    CoverageMap,
    RotationDiversity,
    coverage_map,
    rotation_diversity,
)
from vision.calibration.patterns import Detection, ProgressFn, detect_patterns
from vision.camera import PinholeCamera
from vision.errors import CalibrationError

__all__ = [
    "IntrinsicsOptions",
    "IntrinsicsResult",
    "RejectedView",
    "ViewResidual",
    "calibrate_intrinsics",
    "calibrate_intrinsics_from_detections",
    "pose_from_rvec",
    "single_threaded_opencv",
]

_CRITERIA = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 200, 1e-12)


_THREADS_LOCK = threading.Lock()


@contextmanager
def single_threaded_opencv() -> Iterator[None]:
    """Run OpenCV single-threaded inside the block, so that its sums come out in one order.

    ``calibrateCamera`` accumulates its normal equations in parallel; with several threads
    the last bits of the answer depend on scheduling, and a stored session would not
    re-solve to exactly the same numbers.  The thread count is process-wide, so blocks are
    serialised and the previous count is restored.
    """
    with _THREADS_LOCK:
        before = cv2.getNumThreads()
        cv2.setNumThreads(1)
        try:
            yield
        finally:
            cv2.setNumThreads(before)


def pose_from_rvec(rvec: Any, tvec: Any) -> NDArray[np.float64]:
    """4x4 pose from an OpenCV rotation vector and translation."""
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64).reshape(3, 1))[0]
    T[:3, 3] = np.asarray(tvec, dtype=np.float64).ravel()
    return T


@dataclass(frozen=True)
class IntrinsicsOptions:
    """What the intrinsic solve estimates and how it treats outliers.

    Attributes
    ----------
    radial_only : bool
        Hold the tangential terms p1 = p2 = 0 (the chapter's advice for stability).
    k3 : bool
        Also estimate the third radial term k3 (wide-angle lenses).
    fix_aspect_ratio : bool
        Estimate one focal length (fx = fy).
    reject_outliers : bool
        Drop views whose RMS exceeds ``outlier_factor`` times the median and
        ``outlier_floor_px``, one at a time, re-solving after each.
    outlier_factor : float
        See ``reject_outliers``.
    outlier_floor_px : float
        See ``reject_outliers``: views under this RMS are never outliers.
    min_views : int
        Fewer usable views than this is an error.
    """

    radial_only: bool = False
    k3: bool = False
    fix_aspect_ratio: bool = False
    reject_outliers: bool = True
    outlier_factor: float = 3.0
    outlier_floor_px: float = 0.5
    min_views: int = 4

    def __post_init__(self) -> None:
        if not self.outlier_factor > 1.0:
            raise ValueError(f"outlier_factor must be > 1, got {self.outlier_factor!r}")
        if not self.outlier_floor_px >= 0.0:
            raise ValueError(f"outlier_floor_px must be >= 0, got {self.outlier_floor_px!r}")
        if int(self.min_views) != self.min_views or self.min_views < 3:
            raise ValueError(f"min_views must be an integer >= 3, got {self.min_views!r}")

    @property
    def flags(self) -> int:
        """The ``cv2.calibrateCamera`` flags."""
        f = 0
        if not self.k3:
            f |= cv2.CALIB_FIX_K3
        if self.radial_only:
            f |= cv2.CALIB_ZERO_TANGENT_DIST
        if self.fix_aspect_ratio:
            f |= cv2.CALIB_FIX_ASPECT_RATIO
        return f

    def describe(self) -> str:
        """The distortion model in words, e.g. ``k1, k2, p1, p2``."""
        terms = ["k1", "k2"]
        if not self.radial_only:
            terms += ["p1", "p2"]
        if self.k3:
            terms.append("k3")
        return ", ".join(terms) + (" (fx = fy)" if self.fix_aspect_ratio else "")

    def as_dict(self) -> dict[str, Any]:
        """JSON form."""
        return {
            "radial_only": self.radial_only,
            "k3": self.k3,
            "fix_aspect_ratio": self.fix_aspect_ratio,
            "reject_outliers": self.reject_outliers,
            "outlier_factor": self.outlier_factor,
            "outlier_floor_px": self.outlier_floor_px,
            "min_views": self.min_views,
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> IntrinsicsOptions:
        """Inverse of :meth:`as_dict` (unknown keys are an error)."""
        unknown = set(d) - set(cls().as_dict())
        if unknown:
            raise ValueError(f"unknown intrinsics options: {', '.join(sorted(unknown))}")
        return cls(**d)


@dataclass(frozen=True)
class ViewResidual:
    """Reprojection error of one view used in the solve.

    Attributes
    ----------
    index : int
        Position of the image in the input.
    name : str
        Its name (file name where known).
    rms_px, max_px : float
        RMS and largest corner reprojection error, pixels.
    n_points : int
        Corners used.
    T_cam_board : ndarray of shape (4, 4)
        The board pose estimated with the intrinsics, metres.
    """

    index: int
    name: str
    rms_px: float
    max_px: float
    n_points: int
    T_cam_board: NDArray[np.float64]

    def as_dict(self) -> dict[str, Any]:
        """JSON form."""
        return {
            "index": self.index,
            "name": self.name,
            "rms_px": self.rms_px,
            "max_px": self.max_px,
            "n_points": self.n_points,
            "T_cam_board": self.T_cam_board.tolist(),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ViewResidual:
        """Inverse of :meth:`as_dict`."""
        return cls(
            int(d["index"]),
            str(d["name"]),
            float(d["rms_px"]),
            float(d["max_px"]),
            int(d["n_points"]),
            np.asarray(d["T_cam_board"], dtype=np.float64),
        )


@dataclass(frozen=True)
class RejectedView:
    """An image kept out of a solve, with the reason (no pattern, outlier, ...)."""

    index: int
    name: str
    reason: str

    def as_dict(self) -> dict[str, Any]:
        """JSON form."""
        return {"index": self.index, "name": self.name, "reason": self.reason}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> RejectedView:
        """Inverse of :meth:`as_dict`."""
        return cls(int(d["index"]), str(d["name"]), str(d["reason"]))


@dataclass(frozen=True)
class IntrinsicsResult:
    """A solved intrinsic calibration.

    Attributes
    ----------
    K : ndarray of shape (3, 3)
        Camera matrix (eq. 2), pixels.
    dist : ndarray of shape (5,)
        ``(k1, k2, p1, p2, k3)`` (eqs. 3-5); fixed terms are 0.
    rms_px : float
        RMS reprojection error over all corners of the views used, pixels.
    image_size : tuple of int
        ``(width, height)``.
    std_K : ndarray of shape (4,)
        Standard deviations of ``(fx, fy, cx, cy)``, pixels.
    std_dist : ndarray of shape (5,)
        Standard deviations of the distortion terms (0 for fixed terms).
    views : tuple of ViewResidual
        The views used, in input order.
    rejected : tuple of RejectedView
        The views left out and why.
    coverage : CoverageMap
        Where the corners of the used views lie.
    diversity : RotationDiversity
        How varied the board orientations of the used views are.
    options : IntrinsicsOptions
        The options of the solve.
    board : dict
        The board, as ``Board.as_dict()``.
    """

    K: NDArray[np.float64]
    dist: NDArray[np.float64]
    rms_px: float
    image_size: tuple[int, int]
    std_K: NDArray[np.float64]
    std_dist: NDArray[np.float64]
    views: tuple[ViewResidual, ...]
    rejected: tuple[RejectedView, ...]
    coverage: CoverageMap
    diversity: RotationDiversity
    options: IntrinsicsOptions = field(default_factory=IntrinsicsOptions)
    board: dict[str, Any] = field(default_factory=dict)

    @property
    def camera(self) -> PinholeCamera:
        """The calibrated camera model."""
        return PinholeCamera(self.K, self.dist, width=self.image_size[0], height=self.image_size[1])

    @property
    def n_points(self) -> int:
        """Corners used in the solve."""
        return int(sum(v.n_points for v in self.views))

    def as_dict(self) -> dict[str, Any]:
        """JSON form (what the database stores)."""
        return {
            "kind": "intrinsic",
            "K": self.K.tolist(),
            "dist": self.dist.tolist(),
            "rms_px": self.rms_px,
            "image_size": list(self.image_size),
            "std_K": self.std_K.tolist(),
            "std_dist": self.std_dist.tolist(),
            "views": [v.as_dict() for v in self.views],
            "rejected": [r.as_dict() for r in self.rejected],
            "coverage": self.coverage.as_dict(),
            "diversity": self.diversity.as_dict(),
            "options": self.options.as_dict(),
            "board": dict(self.board),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> IntrinsicsResult:
        """Inverse of :meth:`as_dict`."""
        size = [int(v) for v in d["image_size"]]
        return cls(
            K=np.asarray(d["K"], dtype=np.float64),
            dist=np.asarray(d["dist"], dtype=np.float64),
            rms_px=float(d["rms_px"]),
            image_size=(size[0], size[1]),
            std_K=np.asarray(d["std_K"], dtype=np.float64),
            std_dist=np.asarray(d["std_dist"], dtype=np.float64),
            views=tuple(ViewResidual.from_dict(v) for v in d["views"]),
            rejected=tuple(RejectedView.from_dict(r) for r in d["rejected"]),
            coverage=CoverageMap.from_dict(d["coverage"]),
            diversity=RotationDiversity.from_dict(d["diversity"]),
            options=IntrinsicsOptions.from_dict(d["options"]),
            board=dict(d.get("board", {})),
        )


def _names(names: Sequence[str] | None, n: int) -> list[str]:
    if names is None:
        return [f"image {i}" for i in range(n)]
    if len(names) != n:
        raise ValueError(f"names must have one entry per image ({n}), got {len(names)}")
    return [str(s) for s in names]


def _image_size(detections: Sequence[Detection]) -> tuple[int, int]:
    sizes = {d.image_size for d in detections}
    if len(sizes) != 1:
        raise CalibrationError(
            "all images of an intrinsic calibration must have the same size, got "
            + ", ".join(f"{w}x{h}" for w, h in sorted(sizes))
        )
    return next(iter(sizes))


def _solve(
    obj: list[NDArray[np.float32]],
    img: list[NDArray[np.float32]],
    size: tuple[int, int],
    flags: int,
) -> tuple[
    float, NDArray[np.float64], NDArray[np.float64], list[NDArray[np.float64]], NDArray[np.float64]
]:
    with single_threaded_opencv():
        rms, K, dist, rvecs, tvecs, std_in, _std_ex, _per_view = cv2.calibrateCameraExtended(
            obj, img, size, np.eye(3), np.zeros(5), flags=flags, criteria=_CRITERIA
        )
    poses = [pose_from_rvec(r, t) for r, t in zip(rvecs, tvecs, strict=True)]
    return (
        float(rms),
        np.asarray(K, dtype=np.float64),
        np.asarray(dist, dtype=np.float64).ravel()[:5],
        poses,
        np.asarray(std_in, dtype=np.float64).ravel(),
    )


def _view_errors(
    obj: NDArray[np.float32], img: NDArray[np.float32], T: NDArray[np.float64], K: Any, dist: Any
) -> NDArray[np.float64]:
    rvec = cv2.Rodrigues(T[:3, :3])[0]
    proj, _ = cv2.projectPoints(obj, rvec, T[:3, 3], K, dist)
    return np.linalg.norm(proj.reshape(-1, 2) - img.reshape(-1, 2), axis=1)


def calibrate_intrinsics_from_detections(
    detections: Sequence[Detection],
    board: Board,
    *,
    names: Sequence[str] | None = None,
    options: IntrinsicsOptions | None = None,
    progress: ProgressFn | None = None,
) -> IntrinsicsResult:
    """Solve ``K`` and ``dist`` (eqs. 2-5) from board detections.

    Parameters
    ----------
    detections : sequence of Detection
        One per image, found or not (those not found are reported as rejected).
    board : Chessboard or CharucoBoard
        The target the detections are of.
    names : sequence of str, optional
        Image names for the report.
    options : IntrinsicsOptions, optional
        Distortion model and outlier handling (default: k1, k2, p1, p2; outliers dropped).
    progress : callable, optional
        Called as ``progress(fraction, message)``.

    Raises
    ------
    CalibrationError
        Fewer than ``options.min_views`` usable views, or images of different sizes.
    """
    opts = options or IntrinsicsOptions()
    if not detections:
        raise CalibrationError("no images to calibrate from")
    labels = _names(names, len(detections))
    rejected: list[RejectedView] = []
    used: list[int] = []
    for i, d in enumerate(detections):
        if not d.found:
            rejected.append(RejectedView(i, labels[i], d.reason or "pattern not found"))
        elif d.n_points < 6:
            rejected.append(RejectedView(i, labels[i], f"only {d.n_points} corners, need 6"))
        else:
            used.append(i)
    size = _image_size([detections[i] for i in used] or list(detections))

    def too_few() -> CalibrationError:
        why = "; ".join(f"{r.name}: {r.reason}" for r in rejected) or "none"
        return CalibrationError(
            f"need at least {opts.min_views} views with the board, got {len(used)} "
            f"of {len(detections)} (rejected: {why})"
        )

    if len(used) < opts.min_views:
        raise too_few()
    obj_all = {i: detections[i].object_points(board).astype(np.float32) for i in used}
    img_all = {i: detections[i].image_points.astype(np.float32) for i in used}
    step = 0
    while True:
        step += 1
        if progress is not None:
            progress(min(0.9, 0.2 * step), f"solving with {len(used)} views")
        try:
            rms, K, dist, poses, std = _solve(
                [obj_all[i] for i in used], [img_all[i] for i in used], size, opts.flags
            )
        except cv2.error as exc:
            raise CalibrationError(f"the intrinsic solve failed: {exc.err}") from None
        errs = [
            _view_errors(obj_all[i], img_all[i], T, K, dist)
            for i, T in zip(used, poses, strict=True)
        ]
        view_rms = np.array([float(np.sqrt(np.mean(e**2))) for e in errs])
        if not opts.reject_outliers:
            break
        med = float(np.median(view_rms))
        limit = max(opts.outlier_factor * med, opts.outlier_floor_px)
        worst = int(np.argmax(view_rms))
        if view_rms[worst] <= limit:
            break
        if len(used) - 1 < opts.min_views:
            # Dropping the outlier would leave too few views: keep it and say so.
            break
        i = used.pop(worst)
        rejected.append(
            RejectedView(
                i,
                labels[i],
                f"outlier: reprojection RMS {view_rms[worst]:.2f} px > {limit:.2f} px "
                f"({opts.outlier_factor:g} x the median {med:.2f} px)",
            )
        )
    if not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0:
        raise CalibrationError(f"the intrinsic solve diverged: K = {K.tolist()}")
    views = tuple(
        ViewResidual(i, labels[i], float(r), float(e.max()), int(e.size), T)
        for i, r, e, T in zip(used, view_rms, errs, poses, strict=True)
    )
    rejected.sort(key=lambda r: r.index)
    result = IntrinsicsResult(
        K=K,
        dist=np.concatenate([dist, np.zeros(5 - dist.size)]),
        rms_px=rms,
        image_size=size,
        std_K=std[:4].copy(),
        std_dist=std[4:9].copy(),
        views=views,
        rejected=tuple(rejected),
        coverage=coverage_map([img_all[i] for i in used], size),
        diversity=rotation_diversity(np.array(poses)),
        options=opts,
        board=board.as_dict(),
    )
    if progress is not None:
        progress(1.0, f"RMS {rms:.3f} px over {len(used)} views")
    return result


def calibrate_intrinsics(
    images: Sequence[NDArray[np.uint8]],
    board: Board,
    *,
    names: Sequence[str] | None = None,
    options: IntrinsicsOptions | None = None,
    progress: ProgressFn | None = None,
) -> IntrinsicsResult:
    """Detect ``board`` in every image and solve the intrinsics (chapter eqs. 1-5).

    Parameters
    ----------
    images : sequence of ndarray of shape (H, W) or (H, W, 3), uint8
        Greyscale or RGB views of the board, all of one size.
    board : Chessboard or CharucoBoard
        The target.
    names, options, progress
        As in :func:`calibrate_intrinsics_from_detections`.

    Returns
    -------
    IntrinsicsResult
        With ``.rms_px``, ``.K``, ``.dist``, per-view residuals, rejected views, standard
        deviations and the coverage map.

    Examples
    --------
    >>> from vision.calibration import Chessboard, calibrate_intrinsics
    >>> result = calibrate_intrinsics(images, Chessboard(9, 6, 0.025))  # doctest: +SKIP
    >>> result.rms_px, result.K[0, 0]  # doctest: +SKIP
    """
    if isinstance(board, dict):
        board = board_from_dict(board)

    def det_progress(f: float, msg: str) -> None:
        if progress is not None:
            progress(0.8 * f, msg)

    detections = detect_patterns(images, board, progress=det_progress)

    def solve_progress(f: float, msg: str) -> None:
        if progress is not None:
            progress(0.8 + 0.2 * f, msg)

    return calibrate_intrinsics_from_detections(
        detections, board, names=names, options=options, progress=solve_progress
    )
