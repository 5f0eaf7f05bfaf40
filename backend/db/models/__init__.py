"""SQLAlchemy 2 models of VisionCell; ``migrations/`` holds the matching Alembic revisions.

Tables: users and their API tokens (hashed), cells, object models and their trained views,
calibration sessions with their samples and solutions, inspections with their images, and
the recognition settings.  Timestamps are timezone-aware UTC (:class:`UTCDateTime`).

Each concern has its own submodule (:mod:`~backend.db.models.base` holds the declarative
base and the enumerations); this package re-exports every model, and importing it registers
every table in ``Base.metadata``.
"""

from __future__ import annotations

from backend.db.models.accounts import ApiToken, AuditEntry, Cell, User
from backend.db.models.base import Base, CalibrationKind, Decision, ObjectKind, Role
from backend.db.models.calibration import Calibration, CalibrationSample, CalibrationSession
from backend.db.models.inspection import (
    Inspection,
    InspectionImage,
    InspectionScene,
    InspectionStage,
)
from backend.db.models.journal import InspectionInProgress, JobInProgress
from backend.db.models.recipes import Recipe, RecipeSelection
from backend.db.models.recognition import (
    NegativeImage,
    ObjectModel,
    RecognitionSettings,
    StationBackground,
    TrainedView,
)
from backend.db.models.reports import ReportBlock, ReportName

# Some modules take the timestamp default from here, beside the models.
from backend.db.types import utcnow as utcnow

__all__ = [
    "ApiToken",
    "AuditEntry",
    "Base",
    "Calibration",
    "CalibrationKind",
    "CalibrationSample",
    "CalibrationSession",
    "Cell",
    "Decision",
    "Inspection",
    "InspectionImage",
    "InspectionInProgress",
    "InspectionScene",
    "InspectionStage",
    "JobInProgress",
    "NegativeImage",
    "ObjectKind",
    "ObjectModel",
    "Recipe",
    "RecipeSelection",
    "RecognitionSettings",
    "ReportBlock",
    "ReportName",
    "Role",
    "StationBackground",
    "TrainedView",
    "User",
]
