"""SQLAlchemy 2 models of VisionCell; ``migrations/`` holds the matching Alembic revisions.

Tables: users and their API tokens (hashed), cells, object models and their trained views,
calibration sessions with their samples and solutions, inspections with their images, and
the recognition settings.  Timestamps are timezone-aware UTC (:class:`UTCDateTime`).
"""

from __future__ import annotations

import enum
from datetime import datetime
from typing import Any, ClassVar

from sqlalchemy import (
    JSON,
    BigInteger,
    Boolean,
    CheckConstraint,
    Enum,
    Float,
    ForeignKey,
    Index,
    Integer,
    LargeBinary,
    MetaData,
    String,
    Text,
    UniqueConstraint,
    text,
)
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column, relationship

from backend.db.types import UTCDateTime, utcnow

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

# Stable constraint names so that Alembic migrations are identical on SQLite and PostgreSQL.
NAMING = {
    "ix": "ix_%(column_0_label)s",
    "uq": "uq_%(table_name)s_%(column_0_name)s",
    "ck": "ck_%(table_name)s_%(constraint_name)s",
    "fk": "fk_%(table_name)s_%(column_0_name)s_%(referred_table_name)s",
    "pk": "pk_%(table_name)s",
}


class Base(DeclarativeBase):
    """Declarative base with the naming convention above."""

    metadata = MetaData(naming_convention=NAMING)
    type_annotation_map: ClassVar[dict[Any, Any]] = {
        datetime: UTCDateTime(),
        dict[str, Any]: JSON,
        list[Any]: JSON,
    }


class Role(enum.IntEnum):
    """Access levels, ordered: each role may do everything the lower ones may."""

    viewer = 1
    operator = 2
    engineer = 3


class ObjectKind(enum.StrEnum):
    """Whether recognition needs only the top view (2D) or may visit side views (3D)."""

    two_d = "2d"
    three_d = "3d"


class CalibrationKind(enum.StrEnum):
    """What a calibration solves."""

    intrinsic = "intrinsic"
    hand_eye = "hand_eye"


class Decision(enum.StrEnum):
    """Outcome of one inspection."""

    recognized = "recognized"
    unknown = "unknown"
    failed = "failed"


def _enum(cls: type[enum.Enum], name: str) -> Enum:
    return Enum(
        cls, name=name, native_enum=False, values_callable=lambda c: [m.value for m in c], length=16
    )


class User(Base):
    """A person or a program that uses the API."""

    __tablename__ = "users"

    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(String(64), unique=True)
    role: Mapped[str] = mapped_column(String(16))
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    disabled: Mapped[bool] = mapped_column(Boolean, default=False)

    tokens: Mapped[list[ApiToken]] = relationship(
        back_populates="user", cascade="all, delete-orphan"
    )

    __table_args__ = (CheckConstraint("role IN ('viewer', 'operator', 'engineer')", name="role"),)


class ApiToken(Base):
    """A bearer token; only its HMAC-SHA256 hash is stored."""

    __tablename__ = "api_tokens"

    id: Mapped[int] = mapped_column(primary_key=True)
    user_id: Mapped[int] = mapped_column(ForeignKey("users.id", ondelete="CASCADE"), index=True)
    token_hash: Mapped[str] = mapped_column(String(64), unique=True)
    prefix: Mapped[str] = mapped_column(String(12))
    label: Mapped[str] = mapped_column(String(64), default="")
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    last_used_at: Mapped[datetime | None] = mapped_column(default=None)
    revoked: Mapped[bool] = mapped_column(Boolean, default=False)
    expires_at: Mapped[datetime | None] = mapped_column(default=None)
    """After this instant the token signs nobody in (None: no expiry)."""

    user: Mapped[User] = relationship(back_populates="tokens")


class Cell(Base):
    """One robot cell (a plant database may hold several)."""

    __tablename__ = "cells"

    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(String(64), unique=True)
    description: Mapped[str] = mapped_column(Text, default="")
    created_at: Mapped[datetime] = mapped_column(default=utcnow)


class ObjectModel(Base):
    """A trainable object; an object with two sitting bases is two models (chapter 3.5.3)."""

    __tablename__ = "object_models"

    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(String(64), unique=True)
    #: The physical part (sorting has one bin per part); the sitting bases of one part are
    #: separate models sharing it (chapter 3.5.3).
    part: Mapped[str] = mapped_column(String(64), index=True, server_default="")
    kind: Mapped[ObjectKind] = mapped_column(_enum(ObjectKind, "object_kind"))
    sitting_base: Mapped[str] = mapped_column(String(64), default="default")
    threshold: Mapped[float | None] = mapped_column(Float, default=None)
    description: Mapped[str] = mapped_column(Text, default="")
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    #: Height above the sitting base, metres (migration 0008): what the pick plans with.
    height_m: Mapped[float | None] = mapped_column(Float, default=None)
    #: The suction point on the upper surface, object frame, metres (all three or none).
    grasp_x_m: Mapped[float | None] = mapped_column(Float, default=None)
    grasp_y_m: Mapped[float | None] = mapped_column(Float, default=None)
    grasp_z_m: Mapped[float | None] = mapped_column(Float, default=None)
    #: Where height and grasp came from: ``measured`` (teach), ``entered`` (engineer) or "".
    geometry_source: Mapped[str] = mapped_column(String(16), default="", server_default="")

    views: Mapped[list[TrainedView]] = relationship(
        back_populates="model", cascade="all, delete-orphan"
    )

    __table_args__ = (
        CheckConstraint(
            "threshold IS NULL OR (threshold >= 0 AND threshold <= 1)", name="threshold_range"
        ),
        CheckConstraint(
            "height_m IS NULL OR (height_m > 0 AND height_m <= 0.5)", name="height_range"
        ),
    )


class TrainedView(Base):
    """One trained image of a model from viewpoint 1 (top), 2 or 3 (sides), with its features."""

    __tablename__ = "trained_views"

    id: Mapped[int] = mapped_column(primary_key=True)
    model_id: Mapped[int] = mapped_column(
        ForeignKey("object_models.id", ondelete="CASCADE"), index=True
    )
    viewpoint: Mapped[int] = mapped_column(Integer)
    image_png: Mapped[bytes] = mapped_column(LargeBinary)
    #: The object's region (PNG, one channel, 255 inside), None when the whole image is used.
    mask_png: Mapped[bytes | None] = mapped_column(LargeBinary, default=None)
    #: Small JPEG of the view for lists (longest side ``THUMBNAIL_PX``).
    thumbnail_jpeg: Mapped[bytes | None] = mapped_column(LargeBinary, default=None)
    width: Mapped[int] = mapped_column(Integer, server_default="0")
    height: Mapped[int] = mapped_column(Integer, server_default="0")
    #: Features in :meth:`vision.features.Features.to_bytes` form (what the index adds).
    features: Mapped[bytes] = mapped_column(LargeBinary)
    descriptor_kind: Mapped[str] = mapped_column(String(32))
    descriptor_version: Mapped[str] = mapped_column(String(32))
    keypoint_count: Mapped[int] = mapped_column(Integer, default=0)
    #: Object yaw about the belt normal relative to the model's frame when taught, radians.
    yaw_rad: Mapped[float] = mapped_column(Float, server_default="0")
    #: Camera roll about its optical axis (joint q5) the view was taken with, radians.
    roll_rad: Mapped[float] = mapped_column(Float, server_default="0")
    #: ``teach`` (the arm took it), ``upload`` (REST) or ``import`` (CLI folder).
    source: Mapped[str] = mapped_column(String(16), server_default="upload")
    #: Joints (rad) and camera pose (4x4, metres) at exposure, when the arm took the view.
    joints: Mapped[list[Any] | None] = mapped_column(JSON, default=None)
    T_base_cam: Mapped[list[Any] | None] = mapped_column(JSON, default=None)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)

    model: Mapped[ObjectModel] = relationship(back_populates="views")

    __table_args__ = (
        CheckConstraint("viewpoint BETWEEN 1 AND 3", name="viewpoint_range"),
        CheckConstraint("source IN ('teach', 'upload', 'import')", name="source"),
    )


class CalibrationSession(Base):
    """A set of calibration samples gathered together (automatic run or upload)."""

    __tablename__ = "calibration_sessions"

    id: Mapped[int] = mapped_column(primary_key=True)
    cell_id: Mapped[int] = mapped_column(ForeignKey("cells.id", ondelete="CASCADE"), index=True)
    kind: Mapped[CalibrationKind] = mapped_column(_enum(CalibrationKind, "calibration_kind"))
    source: Mapped[str] = mapped_column(String(16), default="upload")
    board: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    note: Mapped[str] = mapped_column(Text, default="")
    created_at: Mapped[datetime] = mapped_column(default=utcnow)

    samples: Mapped[list[CalibrationSample]] = relationship(
        back_populates="session", cascade="all, delete-orphan", order_by="CalibrationSample.index"
    )
    calibrations: Mapped[list[Calibration]] = relationship(back_populates="session")


class CalibrationSample(Base):
    """One image of a calibration session with the robot state and the detection outcome."""

    __tablename__ = "calibration_samples"

    id: Mapped[int] = mapped_column(primary_key=True)
    session_id: Mapped[int] = mapped_column(
        ForeignKey("calibration_sessions.id", ondelete="CASCADE"), index=True
    )
    index: Mapped[int] = mapped_column(Integer)
    name: Mapped[str] = mapped_column(String(255), default="", server_default="")
    image_png: Mapped[bytes] = mapped_column(LargeBinary)
    joints: Mapped[list[Any] | None] = mapped_column(JSON, default=None)
    T_base_ee: Mapped[list[Any] | None] = mapped_column(JSON, default=None)
    corners: Mapped[list[Any] | None] = mapped_column(JSON, default=None)
    accepted: Mapped[bool] = mapped_column(Boolean, default=False)
    reason: Mapped[str] = mapped_column(Text, default="")
    created_at: Mapped[datetime] = mapped_column(default=utcnow)

    session: Mapped[CalibrationSession] = relationship(back_populates="samples")

    __table_args__ = (
        UniqueConstraint("session_id", "index", name="uq_calibration_samples_session_index"),
    )


class Calibration(Base):
    """A solved calibration: parameters, residuals and whether it is the active one."""

    __tablename__ = "calibrations"

    id: Mapped[int] = mapped_column(primary_key=True)
    cell_id: Mapped[int] = mapped_column(ForeignKey("cells.id", ondelete="CASCADE"), index=True)
    session_id: Mapped[int | None] = mapped_column(
        ForeignKey("calibration_sessions.id", ondelete="SET NULL"), index=True, default=None
    )
    kind: Mapped[CalibrationKind] = mapped_column(_enum(CalibrationKind, "calibration_kind"))
    parameters: Mapped[dict[str, Any]] = mapped_column(JSON)
    residuals: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    options: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    sample_count: Mapped[int] = mapped_column(Integer)
    rms_px: Mapped[float | None] = mapped_column(Float, default=None)
    active: Mapped[bool] = mapped_column(Boolean, default=False)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)

    session: Mapped[CalibrationSession | None] = relationship(back_populates="calibrations")

    __table_args__ = (
        # At most one active calibration of each kind per cell.
        Index(
            "uq_calibrations_active",
            "cell_id",
            "kind",
            unique=True,
            sqlite_where=text("active"),
            postgresql_where=text("active"),
        ),
    )


class Inspection(Base):
    """One run of the recognition loop on one object."""

    __tablename__ = "inspections"

    id: Mapped[int] = mapped_column(primary_key=True)
    cell_id: Mapped[int] = mapped_column(ForeignKey("cells.id", ondelete="CASCADE"), index=True)
    started_at: Mapped[datetime] = mapped_column(default=utcnow, index=True)
    finished_at: Mapped[datetime | None] = mapped_column(default=None)
    decision: Mapped[Decision] = mapped_column(_enum(Decision, "decision"))
    model_id: Mapped[int | None] = mapped_column(
        ForeignKey("object_models.id", ondelete="SET NULL"), default=None
    )
    score: Mapped[float | None] = mapped_column(Float, default=None)
    viewpoints_visited: Mapped[list[Any]] = mapped_column(JSON, default=list)
    object_pose: Mapped[list[Any] | None] = mapped_column(JSON, default=None)
    duration_s: Mapped[float | None] = mapped_column(Float, default=None)
    note: Mapped[str] = mapped_column(Text, default="")
    #: Name of the recognised model when inspected (kept if the model is deleted later).
    model_name: Mapped[str | None] = mapped_column(String(64), default=None)
    #: Recognition policy (``naive``, ``top-only``, ``two-views``, ``best-next``).
    policy: Mapped[str] = mapped_column(String(16), server_default="two-views", index=True)
    #: Why the decision is what it is (the failure's cause for ``failed``).
    reason: Mapped[str] = mapped_column(Text, server_default="")
    #: Seconds per stage (move, settle, acquire, segment, features, match, decide, pose, pick).
    durations: Mapped[dict[str, Any] | None] = mapped_column(JSON, default=dict)
    #: Fused score of every model considered.
    scores: Mapped[dict[str, Any] | None] = mapped_column(JSON, default=dict)
    #: Pose details (position, yaw, source of the camera model, belt prediction).
    pose: Mapped[dict[str, Any] | None] = mapped_column(JSON, default=None)
    #: Pick and sort outcome (bin, ok, stage, reason) or None when not sorted.
    pick: Mapped[dict[str, Any] | None] = mapped_column(JSON, default=None)
    #: Simulator only, for evaluation: catalogue name and true pose (the decision never reads it).
    truth: Mapped[dict[str, Any] | None] = mapped_column(JSON, default=None)
    #: Where the images came from: ``cell`` (the arm's camera) or ``upload`` (an image sent
    #: to ``POST /api/recognition/recognise``).
    source: Mapped[str] = mapped_column(String(16), server_default="cell", default="cell")
    #: The recipe the inspection ran under (None: none; no foreign key, so the row keeps it
    #: after the recipe is deleted) and its name then.
    recipe_id: Mapped[int | None] = mapped_column(Integer, default=None)
    recipe_name: Mapped[str | None] = mapped_column(String(64), default=None)

    images: Mapped[list[InspectionImage]] = relationship(
        back_populates="inspection", cascade="all, delete-orphan"
    )

    __table_args__ = (
        # The reports' percentiles (ORDER BY .. OFFSET walks these; migration 0007).
        Index("ix_inspections_report_duration", "duration_s"),
        Index("ix_inspections_report_model_score", "model_name", "score"),
        Index("ix_inspections_report_cell_time", "cell_id", "started_at"),
    )


class InspectionImage(Base):
    """An image taken during an inspection, with the viewpoint it was taken from."""

    __tablename__ = "inspection_images"

    id: Mapped[int] = mapped_column(primary_key=True)
    inspection_id: Mapped[int] = mapped_column(
        ForeignKey("inspections.id", ondelete="CASCADE"), index=True
    )
    viewpoint: Mapped[int] = mapped_column(Integer)
    image_jpeg: Mapped[bytes] = mapped_column(LargeBinary)
    scores: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)

    inspection: Mapped[Inspection] = relationship(back_populates="images")


class InspectionStage(Base):
    """Seconds one inspection spent in one stage (a copy of ``inspections.durations`` as rows,
    with the columns the reports filter on), so that stage percentiles walk an index."""

    __tablename__ = "inspection_stages"

    id: Mapped[int] = mapped_column(primary_key=True)
    inspection_id: Mapped[int] = mapped_column(
        ForeignKey("inspections.id", ondelete="CASCADE"), index=True
    )
    stage: Mapped[str] = mapped_column(String(16))
    seconds: Mapped[float] = mapped_column(Float)
    cell_id: Mapped[int] = mapped_column(Integer)
    started_at: Mapped[datetime] = mapped_column()
    decision: Mapped[str] = mapped_column(String(16))
    model_name: Mapped[str | None] = mapped_column(String(64), default=None)
    policy: Mapped[str] = mapped_column(String(16))

    __table_args__ = (
        # Unfiltered percentiles walk the first; filtered ones seek the others (migration 0007).
        Index("ix_inspection_stages_stage_seconds", "stage", "seconds"),
        Index("ix_inspection_stages_stage_cell_time", "stage", "cell_id", "started_at"),
        Index("ix_inspection_stages_stage_model", "stage", "model_name", "seconds"),
    )


class InspectionScene(Base):
    """The 3D scene recorded during an inspection (viser's scene serializer, ``.viser`` bytes)."""

    __tablename__ = "inspection_scenes"

    id: Mapped[int] = mapped_column(primary_key=True)
    inspection_id: Mapped[int] = mapped_column(
        ForeignKey("inspections.id", ondelete="CASCADE"), unique=True
    )
    scene: Mapped[bytes] = mapped_column(LargeBinary)
    #: ``len(scene)``, kept so that the storage used is a sum over a small column.
    size_bytes: Mapped[int] = mapped_column(Integer)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)


class NegativeImage(Base):
    """An image of no trained object (the empty belt, other things in the scene): an
    impostor the automatic threshold is chosen against, shared by the plant as the models."""

    __tablename__ = "negative_images"

    id: Mapped[int] = mapped_column(primary_key=True)
    image_png: Mapped[bytes] = mapped_column(LargeBinary)
    width: Mapped[int] = mapped_column(Integer)
    height: Mapped[int] = mapped_column(Integer)
    #: ``upload`` (sent by an engineer) or ``teach`` (an empty-belt background of a teach).
    source: Mapped[str] = mapped_column(String(16), default="upload")
    note: Mapped[str] = mapped_column(String(200), default="")
    created_at: Mapped[datetime] = mapped_column(default=utcnow)


class RecognitionSettings(Base):
    """The global recognition threshold and how it was chosen (one row per change; the latest applies)."""

    __tablename__ = "recognition_settings"

    id: Mapped[int] = mapped_column(primary_key=True)
    global_threshold: Mapped[float] = mapped_column(Float)
    chosen_by: Mapped[str] = mapped_column(String(32))
    detail: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)

    __table_args__ = (
        CheckConstraint("global_threshold >= 0 AND global_threshold <= 1", name="threshold_range"),
    )


class AuditEntry(Base):
    """One recorded change (the audit trail): who, when, what, old and new value, why.

    Written by :func:`backend.audit.record` in the transaction of the change itself; no API
    edits or deletes these rows.
    """

    __tablename__ = "audit_log"

    id: Mapped[int] = mapped_column(primary_key=True)
    at: Mapped[datetime] = mapped_column(default=utcnow, index=True)
    #: User name, or ``cli`` / ``system`` for command-line and automatic changes.
    actor: Mapped[str] = mapped_column(String(64), index=True)
    actor_role: Mapped[str] = mapped_column(String(16))
    kind: Mapped[str] = mapped_column(String(16))
    entity_id: Mapped[str] = mapped_column(String(64))
    action: Mapped[str] = mapped_column(String(32))
    old: Mapped[dict[str, Any] | None] = mapped_column(JSON, default=None)
    new: Mapped[dict[str, Any] | None] = mapped_column(JSON, default=None)
    reason: Mapped[str] = mapped_column(Text, default="")

    __table_args__ = (
        Index("ix_audit_log_kind_entity", "kind", "entity_id"),
        CheckConstraint(
            "kind IN ('threshold', 'model', 'view', 'negative', 'calibration', 'user', 'token', "
            "'estop', 'recipe')",
            name="kind",
        ),
    )


class InspectionInProgress(Base):
    """The durable marker of an inspection that has started and not yet stored its result.

    Written (committed) before the arm moves for the inspection and deleted in the same
    transaction that writes the :class:`Inspection` row, so a marker that is still there at
    start-up names an inspection cut short by the process ending (issue 16, part 1); the
    start-up turns it into a complete ``failed`` row with the reason ``interrupted``.
    """

    __tablename__ = "inspections_in_progress"

    id: Mapped[int] = mapped_column(primary_key=True)
    cell_id: Mapped[int] = mapped_column(ForeignKey("cells.id", ondelete="CASCADE"), index=True)
    started_at: Mapped[datetime] = mapped_column(default=utcnow)
    policy: Mapped[str] = mapped_column(String(16))
    #: Process that started it (host:pid), for the interruption's reason.
    owner: Mapped[str] = mapped_column(String(128), default="")


class JobInProgress(Base):
    """The durable marker of a job (a move, a teach, an inspection or a run, a calibration)
    that has started and not yet ended.

    Written when the job starts and deleted when it ends (:mod:`backend.jobjournal`), so a
    marker still there at start-up names a job cut short by the process ending; the
    start-up lists it in the jobs as ``interrupted`` and deletes the marker.
    """

    __tablename__ = "jobs_in_progress"

    #: The job's id (as ``/api/jobs`` shows it).
    id: Mapped[str] = mapped_column(String(64), primary_key=True)
    cell_id: Mapped[int] = mapped_column(ForeignKey("cells.id", ondelete="CASCADE"), index=True)
    kind: Mapped[str] = mapped_column(String(64))
    started_at: Mapped[datetime] = mapped_column(default=utcnow)
    #: The job's parameters (small: what the request asked for).
    params: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    #: Process that ran it (host:pid).
    owner: Mapped[str] = mapped_column(String(128), default="")


class StationBackground(Base):
    """An empty-belt background image of one camera shot of a cell (by its joints), kept
    so that a restarted process inspects without teaching again."""

    __tablename__ = "station_backgrounds"

    id: Mapped[int] = mapped_column(primary_key=True)
    cell_id: Mapped[int] = mapped_column(ForeignKey("cells.id", ondelete="CASCADE"), index=True)
    #: The shot's joints, rounded as :class:`backend.recognition.teach.Shot` keys them.
    shot_key: Mapped[list[Any]] = mapped_column(JSON)
    image_png: Mapped[bytes] = mapped_column(LargeBinary)
    taken_at: Mapped[datetime] = mapped_column(default=utcnow)


class ReportName(Base):
    """A name the report blocks refer to by a small id (model, policy, true catalogue name)."""

    __tablename__ = "report_names"

    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(String(64), unique=True)


class ReportBlock(Base):
    """The packed report records of one cell's inspections started in one UTC hour, or of
    one part of them (:mod:`backend.reports.blocks`), appended in each inspection's own
    transaction."""

    __tablename__ = "report_blocks"

    id: Mapped[int] = mapped_column(primary_key=True)
    cell_id: Mapped[int] = mapped_column(ForeignKey("cells.id", ondelete="CASCADE"))
    #: Start of the hour, seconds since 1970-01-01 UTC (a multiple of 3600).
    start_s: Mapped[int] = mapped_column(BigInteger)
    #: Part of the hour (0, 1, ..; each holds at most ``blocks.MAX_RECORDS`` records).
    part: Mapped[int] = mapped_column(Integer, default=0)
    #: Number of records in ``data``.
    n: Mapped[int] = mapped_column(Integer)
    #: ``n`` records of :data:`backend.reports.blocks.RECORD`, concatenated.
    data: Mapped[bytes] = mapped_column(LargeBinary)

    __table_args__ = (
        UniqueConstraint("cell_id", "start_s", "part", name="uq_report_blocks_cell_start"),
    )


class Recipe(Base):
    """A named inspection configuration of one cell (:mod:`backend.recipes`): the options a
    run takes from it, the models in play and their bins; a PLC selects it by ``number``."""

    __tablename__ = "recipes"

    id: Mapped[int] = mapped_column(primary_key=True)
    cell_id: Mapped[int] = mapped_column(ForeignKey("cells.id", ondelete="CASCADE"), index=True)
    name: Mapped[str] = mapped_column(String(64))
    #: 1..9999, unique per cell: what a PLC selects the recipe by.
    number: Mapped[int] = mapped_column(Integer)
    description: Mapped[str] = mapped_column(Text, default="")
    #: policy, max_views, sort, threshold (None: the cell's thresholds), belt_mode, speed,
    #: balance_light (:class:`backend.recipes.model.RecipeOptions`).
    options: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    #: Names of the models in play (empty: every trained model).
    models: Mapped[list[Any]] = mapped_column(JSON, default=list)
    #: Model name -> bin name (models not named keep their part's bin).
    bins: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    updated_at: Mapped[datetime] = mapped_column(default=utcnow)

    __table_args__ = (
        UniqueConstraint("cell_id", "name", name="uq_recipes_cell_name"),
        UniqueConstraint("cell_id", "number", name="uq_recipes_cell_number"),
        CheckConstraint("number >= 1 AND number <= 9999", name="number_range"),
    )


class RecipeSelection(Base):
    """The active recipe of a cell: at most one row per cell (its primary key)."""

    __tablename__ = "recipe_selections"

    cell_id: Mapped[int] = mapped_column(
        ForeignKey("cells.id", ondelete="CASCADE"), primary_key=True
    )
    recipe_id: Mapped[int] = mapped_column(ForeignKey("recipes.id", ondelete="CASCADE"))
    activated_at: Mapped[datetime] = mapped_column(default=utcnow)
    #: Who selected it (user name, ``cli``, or a PLC link's name).
    activated_by: Mapped[str] = mapped_column(String(64), default="")
