"""Results and options of the hand-eye solve (see :mod:`vision.calibration.handeye`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vision.calibration.coverage import CoverageMap, RotationDiversity
from vision.calibration.intrinsics import RejectedView

__all__ = [
    "ALL_METHODS",
    "LOSSES",
    "HandEyeCandidate",
    "HandEyeOptions",
    "HandEyeResult",
    "PoseResidual",
]

#: Names of the closed-form solvers: OpenCV's five AX = XB methods, then its two
#: robot-world-hand-eye methods.
ALL_METHODS = ("tsai", "park", "horaud", "andreff", "daniilidis", "shah", "li")
#: Losses of the refinement (``scipy.optimize.least_squares``).
LOSSES = ("linear", "huber", "soft_l1", "cauchy")


@dataclass(frozen=True)
class HandEyeOptions:
    """Choices of the hand-eye solve.

    Attributes
    ----------
    methods : tuple of str
        Closed-form solvers to try (subset of :data:`ALL_METHODS`).
    refine : bool
        Refine the best candidate by reprojection error.
    loss : str
        ``least_squares`` loss: linear, huber, soft_l1 or cauchy.
    f_scale_px : float
        Residual scale of the robust losses, pixels.
    min_poses : int
        Fewer usable samples than this is an error.
    degenerate_angle_deg, degenerate_axis_deg : float
        Below these largest rotation / axis spread the motion cannot determine
        ``T_ee_cam``: an error.
    warn_angle_deg, warn_axis_deg : float
        Below these the solution is weak: a warning.
    outlier_factor, outlier_floor_px : float
        Samples whose PnP RMS exceeds both ``outlier_factor`` times the median and the
        floor are left out (a bad detection would spoil every method).
    """

    methods: tuple[str, ...] = ALL_METHODS
    refine: bool = True
    loss: str = "linear"
    f_scale_px: float = 1.0
    min_poses: int = 4
    degenerate_angle_deg: float = 2.0
    degenerate_axis_deg: float = 3.0
    warn_angle_deg: float = 20.0
    warn_axis_deg: float = 30.0
    outlier_factor: float = 4.0
    outlier_floor_px: float = 1.0

    def __post_init__(self) -> None:
        methods = tuple(self.methods)
        if not methods or any(m not in ALL_METHODS for m in methods):
            raise ValueError(
                f"methods must be a non-empty subset of {ALL_METHODS}, got {self.methods!r}"
            )
        object.__setattr__(self, "methods", methods)
        if self.loss not in LOSSES:
            raise ValueError(f"loss must be one of {', '.join(LOSSES)}, got {self.loss!r}")
        if not self.f_scale_px > 0:
            raise ValueError(f"f_scale_px must be positive, got {self.f_scale_px!r}")
        if int(self.min_poses) != self.min_poses or self.min_poses < 3:
            raise ValueError(f"min_poses must be an integer >= 3, got {self.min_poses!r}")

    def as_dict(self) -> dict[str, Any]:
        """JSON form."""
        return {
            "methods": list(self.methods),
            "refine": self.refine,
            "loss": self.loss,
            "f_scale_px": self.f_scale_px,
            "min_poses": self.min_poses,
            "degenerate_angle_deg": self.degenerate_angle_deg,
            "degenerate_axis_deg": self.degenerate_axis_deg,
            "warn_angle_deg": self.warn_angle_deg,
            "warn_axis_deg": self.warn_axis_deg,
            "outlier_factor": self.outlier_factor,
            "outlier_floor_px": self.outlier_floor_px,
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> HandEyeOptions:
        """Inverse of :meth:`as_dict` (unknown keys are an error)."""
        unknown = set(d) - set(cls().as_dict())
        if unknown:
            raise ValueError(f"unknown hand-eye options: {', '.join(sorted(unknown))}")
        d = dict(d)
        if "methods" in d:
            d["methods"] = tuple(d["methods"])
        return cls(**d)


@dataclass(frozen=True)
class HandEyeCandidate:
    """One closed-form solution and how consistent it is.

    ``rms_px`` reprojects every sample's corners through (*) with the mean predicted board
    pose; ``spread_mm`` / ``spread_deg`` are the RMS distances of the predicted board poses
    from that mean.
    """

    method: str
    T_ee_cam: NDArray[np.float64]
    rms_px: float
    spread_mm: float
    spread_deg: float

    def as_dict(self) -> dict[str, Any]:
        """JSON form."""
        return {
            "method": self.method,
            "T_ee_cam": self.T_ee_cam.tolist(),
            "rms_px": self.rms_px,
            "spread_mm": self.spread_mm,
            "spread_deg": self.spread_deg,
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> HandEyeCandidate:
        """Inverse of :meth:`as_dict`."""
        return cls(
            str(d["method"]),
            np.asarray(d["T_ee_cam"], dtype=np.float64),
            float(d["rms_px"]),
            float(d["spread_mm"]),
            float(d["spread_deg"]),
        )


@dataclass(frozen=True)
class PoseResidual:
    """How well one sample agrees with the solution.

    Attributes
    ----------
    index, name
        The sample.
    translation_mm, rotation_deg : float
        Distance and angle between the board pose predicted from this sample by (*) and
        the solution's ``T_base_board``.
    offset_mm : tuple of float
        The predicted board origin minus the solution's, in the base frame, millimetres.
    rms_px : float
        RMS reprojection error of this sample's corners through the solution.
    pnp_rms_px : float
        RMS of the free PnP fit of this sample alone (the detection noise floor).
    """

    index: int
    name: str
    translation_mm: float
    rotation_deg: float
    offset_mm: tuple[float, float, float]
    rms_px: float
    pnp_rms_px: float

    def as_dict(self) -> dict[str, Any]:
        """JSON form."""
        return {
            "index": self.index,
            "name": self.name,
            "translation_mm": self.translation_mm,
            "rotation_deg": self.rotation_deg,
            "offset_mm": list(self.offset_mm),
            "rms_px": self.rms_px,
            "pnp_rms_px": self.pnp_rms_px,
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> PoseResidual:
        """Inverse of :meth:`as_dict`."""
        o = [float(v) for v in d["offset_mm"]]
        return cls(
            int(d["index"]),
            str(d["name"]),
            float(d["translation_mm"]),
            float(d["rotation_deg"]),
            (o[0], o[1], o[2]),
            float(d["rms_px"]),
            float(d["pnp_rms_px"]),
        )


@dataclass(frozen=True)
class HandEyeResult:
    """A solved eye-in-hand calibration.

    Attributes
    ----------
    T_ee_cam : ndarray of shape (4, 4)
        Pose of the camera in the flange frame, metres (the inverse of eq. 12's H).
    T_base_board : ndarray of shape (4, 4)
        Pose of the board in the base frame, solved together with ``T_ee_cam``.
    method : str
        The closed-form solver whose answer was kept (and refined).
    refined : bool
        Whether the reprojection refinement ran.
    rms_px : float
        RMS reprojection error of all corners through (*), pixels.
    poses : tuple of PoseResidual
        Per-sample residuals.
    candidates : tuple of HandEyeCandidate
        Every closed-form solution tried, with its consistency.
    diversity : RotationDiversity
        Of the robot orientations of the samples used.
    warnings : tuple of str
        Weak motion and other doubts about the result.
    rejected : tuple of RejectedView
        Samples left out and why.
    coverage : CoverageMap
        Where the corners of the samples used lie in the image.
    K, dist : ndarray
        The intrinsics used.
    options : HandEyeOptions
        The options of the solve.
    """

    T_ee_cam: NDArray[np.float64]
    T_base_board: NDArray[np.float64]
    method: str
    refined: bool
    rms_px: float
    poses: tuple[PoseResidual, ...]
    candidates: tuple[HandEyeCandidate, ...]
    diversity: RotationDiversity
    warnings: tuple[str, ...]
    rejected: tuple[RejectedView, ...]
    coverage: CoverageMap
    K: NDArray[np.float64]
    dist: NDArray[np.float64]
    options: HandEyeOptions

    @property
    def T_cam_ee(self) -> NDArray[np.float64]:
        """The chapter's ``H_ee^camera`` of eq. 12 (maps flange points into the camera)."""
        return np.linalg.inv(self.T_ee_cam).astype(np.float64)

    def _stat(self, attr: str) -> tuple[float, float]:
        v = np.array([getattr(p, attr) for p in self.poses])
        return float(np.sqrt(np.mean(v**2))), float(v.max())

    @property
    def consistency_mm(self) -> tuple[float, float]:
        """``(rms, max)`` of the per-sample board position residuals, millimetres."""
        return self._stat("translation_mm")

    @property
    def consistency_deg(self) -> tuple[float, float]:
        """``(rms, max)`` of the per-sample board orientation residuals, degrees."""
        return self._stat("rotation_deg")

    def as_dict(self) -> dict[str, Any]:
        """JSON form (what the database stores)."""
        (mm_rms, mm_max), (deg_rms, deg_max) = self.consistency_mm, self.consistency_deg
        return {
            "kind": "hand_eye",
            "T_ee_cam": self.T_ee_cam.tolist(),
            "T_base_board": self.T_base_board.tolist(),
            "method": self.method,
            "refined": self.refined,
            "rms_px": self.rms_px,
            "consistency": {
                "translation_rms_mm": mm_rms,
                "translation_max_mm": mm_max,
                "rotation_rms_deg": deg_rms,
                "rotation_max_deg": deg_max,
            },
            "poses": [p.as_dict() for p in self.poses],
            "candidates": [c.as_dict() for c in self.candidates],
            "diversity": self.diversity.as_dict(),
            "warnings": list(self.warnings),
            "rejected": [r.as_dict() for r in self.rejected],
            "coverage": self.coverage.as_dict(),
            "K": self.K.tolist(),
            "dist": self.dist.tolist(),
            "options": self.options.as_dict(),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> HandEyeResult:
        """Inverse of :meth:`as_dict`."""
        return cls(
            T_ee_cam=np.asarray(d["T_ee_cam"], dtype=np.float64),
            T_base_board=np.asarray(d["T_base_board"], dtype=np.float64),
            method=str(d["method"]),
            refined=bool(d["refined"]),
            rms_px=float(d["rms_px"]),
            poses=tuple(PoseResidual.from_dict(p) for p in d["poses"]),
            candidates=tuple(HandEyeCandidate.from_dict(c) for c in d["candidates"]),
            diversity=RotationDiversity.from_dict(d["diversity"]),
            warnings=tuple(str(w) for w in d["warnings"]),
            rejected=tuple(RejectedView.from_dict(r) for r in d["rejected"]),
            coverage=CoverageMap.from_dict(d["coverage"]),
            K=np.asarray(d["K"], dtype=np.float64),
            dist=np.asarray(d["dist"], dtype=np.float64),
            options=HandEyeOptions.from_dict(d["options"]),
        )
