"""The cell's building blocks: camera acquisition, motion (``move_to``, ``settle``, ``look``,
``next_frame``), the event bus, and the :class:`Cell` that joins them."""

from backend.cell.camera import CameraFeed
from backend.cell.core import Cell
from backend.cell.errors import MoveAborted, NotStill, PathBlocked
from backend.cell.events import (
    ArmState,
    CalibrationView,
    CameraStatus,
    CellEvent,
    CellStopped,
    EventBus,
    JobProgress,
    JobState,
    Subscription,
)
from backend.cell.motion import STILL_RAD_S, Pose, Target
from backend.cell.viewlog import CalibrationViewLog

__all__ = [
    "STILL_RAD_S",
    "ArmState",
    "CalibrationView",
    "CalibrationViewLog",
    "CameraFeed",
    "CameraStatus",
    "Cell",
    "CellEvent",
    "CellStopped",
    "EventBus",
    "JobProgress",
    "JobState",
    "MoveAborted",
    "NotStill",
    "PathBlocked",
    "Pose",
    "Subscription",
    "Target",
]
