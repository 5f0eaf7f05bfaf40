"""The one table from domain error classes to HTTP statuses (backend.api.errors).

The statuses below are those every error was answered with when each class still carried
its own; the table at the API edge must give the same, and the domain errors themselves
carry no HTTP status.
"""

from __future__ import annotations

import importlib
import pkgutil

import pytest

import backend
import robot
import vision
from backend.api.errors import STATUS_OF_ERROR, status_of
from vision.errors import VisionCellError

#: (module, class, code, HTTP status) of every domain error.
EXPECTED = [
    ("vision.errors", "VisionCellError", "visioncell_error", 400),
    ("vision.errors", "NotFound", "not_found", 404),
    ("backend.auth", "UserExists", "conflict", 409),
    ("backend.calibration.sessions", "OtherCell", "other_cell", 409),
    ("backend.cell.errors", "MoveAborted", "move_aborted", 409),
    ("backend.inspection.errors", "CarriedAway", "carried_away", 409),
    ("backend.inspection.errors", "NoObject", "no_object", 409),
    ("backend.inspection.errors", "NotReady", "nothing_trained", 409),
    ("backend.recognition.index", "StaleFeatures", "stale_features", 409),
    ("backend.recognition.teach", "TeachTimeout", "teach_timeout", 409),
    ("robot.errors", "CommandSuperseded", "command_superseded", 409),
    ("robot.errors", "RobotBusy", "robot_busy", 409),
    ("robot.errors", "RobotError", "robot_error", 409),
    ("robot.errors", "SimError", "sim_error", 409),
    ("vision.errors", "Conflict", "conflict", 409),
    ("vision.errors", "NothingTrained", "nothing_trained", 409),
    ("vision.errors", "StreamEnded", "stream_ended", 409),
    ("vision.recognition.light", "LightChanged", "light_changed", 409),
    ("backend.heavy", "PixelBudgetExceeded", "too_large", 413),
    ("backend.recognition.images", "ImageTooLarge", "too_large", 413),
    ("backend.recognition.images", "UnsupportedImage", "unsupported_media_type", 415),
    ("backend.cell.errors", "PathBlocked", "path_blocked", 422),
    ("backend.recognition.segment", "SegmentationFailed", "segmentation_failed", 422),
    ("backend.recognition.views", "TooFewFeatures", "invalid_value", 422),
    ("robot.errors", "JointLimitError", "joint_limit", 422),
    ("robot.errors", "JointLimitsBlock", "unreachable", 422),
    ("robot.errors", "OrientationNotAchievable", "unreachable", 422),
    ("robot.errors", "OutOfReach", "unreachable", 422),
    ("robot.errors", "TrajectoryTooLong", "trajectory_too_long", 422),
    ("robot.errors", "Unreachable", "unreachable", 422),
    ("vision.errors", "CalibrationError", "calibration_failed", 422),
    ("vision.errors", "ImageError", "bad_image", 422),
    ("vision.errors", "InvalidInput", "invalid_value", 422),
    ("vision.errors", "RecognitionFailed", "recognition_failed", 422),
    ("vision.pose.geometry", "PoseFailed", "pose_failed", 422),
    ("vision.recognition.serial", "IndexFormatError", "bad_view_index", 422),
    ("backend.heavy", "ClientGone", "client_closed_request", 499),
    ("backend.cell.errors", "NotStill", "not_still", 503),
    ("backend.heavy", "Busy", "busy", 503),
    ("robot.errors", "CommandRejected", "command_rejected", 503),
    ("robot.errors", "CommandTimeout", "command_timeout", 503),
    ("robot.errors", "DriverError", "driver_error", 503),
    ("robot.errors", "LinkDown", "link_down", 503),
    ("robot.errors", "ProtocolError", "protocol_error", 503),
    ("vision.errors", "CameraError", "camera_error", 503),
]


def _all_errors() -> set[type[VisionCellError]]:
    for pkg in (vision, robot, backend):
        for info in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + "."):
            if not info.name.endswith("__main__"):
                importlib.import_module(info.name)
    found: set[type[VisionCellError]] = set()
    stack: list[type[VisionCellError]] = [VisionCellError]
    while stack:
        cls = stack.pop()
        found.add(cls)
        stack.extend(cls.__subclasses__())
    return found


@pytest.mark.parametrize(
    ("module", "name", "code", "status"), EXPECTED, ids=[e[1] for e in EXPECTED]
)
def test_each_error_keeps_its_code_and_status(module, name, code, status):
    cls = getattr(importlib.import_module(module), name.split(".")[0])
    assert cls.code == code
    assert status_of(cls) == status


def test_every_error_is_listed_and_none_carries_an_http_status():
    errors = _all_errors()
    assert {(c.__module__, c.__qualname__) for c in errors} == {(m, n) for m, n, _, _ in EXPECTED}
    assert [c.__qualname__ for c in errors if hasattr(c, "http_status")] == []
    assert set(STATUS_OF_ERROR) <= errors


def test_status_of_takes_an_instance_and_its_nearest_listed_base():
    from vision.errors import NotFound, NothingTrained

    assert status_of(NotFound("model 7")) == 404
    assert NothingTrained not in STATUS_OF_ERROR and status_of(NothingTrained("none")) == 409


def test_status_of_refuses_what_is_not_a_domain_error():
    with pytest.raises(TypeError, match="ValueError is not a VisionCellError"):
        status_of(ValueError)  # type: ignore[arg-type]
