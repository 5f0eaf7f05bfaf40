"""Calibration in the running system: sessions and samples in the database, solving as
jobs, activation, history and reports, automatic calibration in the cell (the algorithms
live in ``vision.calibration``)."""

from backend.calibration.auto import (
    AUTO_CRITERIA,
    AutoOptions,
    AutoRun,
    CalibrationViewLog,
    nominal_camera,
    prepare_auto_calibration,
    run_auto_calibration,
)
from backend.calibration.autoplan import (
    NOMINAL_T_EE_CAM,
    AutoPlan,
    PlannedView,
    plan_calibration_poses,
)
from backend.calibration.reports import PLOTS, calibration_public, calibration_report, report_png
from backend.calibration.sessions import (
    NotFound,
    SampleIn,
    add_samples,
    cell_id_of,
    create_session,
    get_session,
    list_sessions,
    load_detections,
    session_summary,
)
from backend.calibration.solving import (
    CameraCalibration,
    SolveOptions,
    SolveOutcome,
    activate,
    active_calibrations,
    active_camera_calibration,
    check_solvable,
    get_calibration,
    history,
    result_of,
    solve_session,
)

__all__ = [
    "AUTO_CRITERIA",
    "NOMINAL_T_EE_CAM",
    "PLOTS",
    "AutoOptions",
    "AutoPlan",
    "AutoRun",
    "CalibrationViewLog",
    "CameraCalibration",
    "NotFound",
    "PlannedView",
    "SampleIn",
    "SolveOptions",
    "SolveOutcome",
    "activate",
    "active_calibrations",
    "active_camera_calibration",
    "add_samples",
    "calibration_public",
    "calibration_report",
    "cell_id_of",
    "check_solvable",
    "create_session",
    "get_calibration",
    "get_session",
    "history",
    "list_sessions",
    "load_detections",
    "nominal_camera",
    "plan_calibration_poses",
    "prepare_auto_calibration",
    "report_png",
    "result_of",
    "run_auto_calibration",
    "session_summary",
    "solve_session",
]
