"""JSON and PNG reports of stored calibrations (millimetres and degrees at this edge)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from backend.calibration.public import CalibrationPublic, CalibrationReport
from backend.calibration.sessions import NotFound
from backend.calibration.solving import result_of
from backend.db.models import Calibration, CalibrationKind
from vision.calibration import HandEyeResult, IntrinsicsResult
from vision.calibration import report as plots

__all__ = ["PLOTS", "calibration_report", "report_png"]

#: The PNG plots a report offers, by name.
PLOTS = ("residuals", "coverage", "consistency")


def _intrinsic_summary(r: IntrinsicsResult) -> dict[str, Any]:
    names = ("fx", "fy", "cx", "cy")
    dnames = ("k1", "k2", "p1", "p2", "k3")
    K = r.K
    values = (K[0, 0], K[1, 1], K[0, 2], K[1, 2])
    return {
        "rms_px": r.rms_px,
        "model": r.options.describe(),
        "image_size": list(r.image_size),
        "intrinsics": {
            n: {"value": float(v), "std": float(s)}
            for n, v, s in zip(names, values, r.std_K, strict=True)
        },
        "distortion": {
            n: {"value": float(v), "std": float(s)}
            for n, v, s in zip(dnames, r.dist, r.std_dist, strict=True)
        },
        "views_used": len(r.views),
        "views_rejected": len(r.rejected),
        "coverage_fraction": r.coverage.fraction,
        "coverage_corner_cells": r.coverage.corner_cells,
        "per_image": [
            {"index": v.index, "name": v.name, "rms_px": v.rms_px, "max_px": v.max_px}
            for v in r.views
        ],
        "rejected": [x.as_dict() for x in r.rejected],
    }


def _hand_eye_summary(r: HandEyeResult) -> dict[str, Any]:
    T = r.T_ee_cam
    (mm_rms, mm_max), (deg_rms, deg_max) = r.consistency_mm, r.consistency_deg
    return {
        "rms_px": r.rms_px,
        "method": r.method,
        "refined": r.refined,
        "T_ee_cam": T.tolist(),
        "T_cam_ee": r.T_cam_ee.tolist(),
        "translation_mm": (T[:3, 3] * 1e3).tolist(),
        "rotation_xyz_deg": Rotation.from_matrix(T[:3, :3]).as_euler("xyz", degrees=True).tolist(),
        "rotation_angle_deg": math.degrees(Rotation.from_matrix(T[:3, :3]).magnitude()),
        "consistency": {
            "translation_rms_mm": mm_rms,
            "translation_max_mm": mm_max,
            "rotation_rms_deg": deg_rms,
            "rotation_max_deg": deg_max,
        },
        "per_pose": [
            {
                "index": p.index,
                "name": p.name,
                "translation_mm": p.translation_mm,
                "rotation_deg": p.rotation_deg,
                "rms_px": p.rms_px,
            }
            for p in r.poses
        ],
        "candidates": [
            {
                "method": c.method,
                "rms_px": c.rms_px,
                "spread_mm": c.spread_mm,
                "spread_deg": c.spread_deg,
                "translation_mm": (np.asarray(c.T_ee_cam)[:3, 3] * 1e3).tolist(),
            }
            for c in r.candidates
        ],
        "diversity": r.diversity.as_dict(),
        "warnings": list(r.warnings),
        "rejected": [x.as_dict() for x in r.rejected],
        "coverage_fraction": r.coverage.fraction,
    }


def _check_solved(cal: Calibration) -> None:
    """:class:`NotFound` for a calibration without a solve's residuals (an imported one)."""
    if not cal.residuals:
        raise NotFound(
            f"calibration {cal.id} has no report: it was not solved here (imported), so it "
            "has no residuals"
        )


def calibration_report(cal: Calibration) -> dict[str, Any]:
    """The report of a calibration as JSON values (:class:`CalibrationReport`): the row, a
    readable summary and the links to its plots."""
    _check_solved(cal)
    result = result_of(cal)
    summary = (
        _intrinsic_summary(result)
        if isinstance(result, IntrinsicsResult)
        else _hand_eye_summary(result)
    )
    available = [p for p in PLOTS if p != "consistency" or cal.kind is CalibrationKind.hand_eye]
    base = f"/api/calibration/calibrations/{cal.id}/report"
    return CalibrationReport(
        calibration=CalibrationPublic.model_validate(cal),
        summary=summary,
        plots={p: f"{base}/{p}.png" for p in available},
    ).model_dump(mode="json")


def report_png(cal: Calibration, plot: str) -> bytes:
    """One of the :data:`PLOTS` of a calibration as PNG bytes."""
    if plot not in PLOTS:
        raise NotFound(f"no plot {plot!r}; there are {', '.join(PLOTS)}")
    _check_solved(cal)
    result = result_of(cal)
    if plot == "residuals":
        return plots.residuals_png(result)
    if plot == "coverage":
        return plots.coverage_png(result.coverage, title=f"Calibration {cal.id}")
    if not isinstance(result, HandEyeResult):
        raise NotFound(f"calibration {cal.id} is intrinsic: it has no consistency plot")
    return plots.consistency_png(result)
