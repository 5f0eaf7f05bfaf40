"""Object models, their trained views, the negative images and recognition settings the
thresholds are chosen with, and the stored empty-belt backgrounds."""

from __future__ import annotations

from datetime import datetime
from typing import Any

from sqlalchemy import JSON, CheckConstraint, Float, ForeignKey, Integer, LargeBinary, String, Text
from sqlalchemy.orm import Mapped, mapped_column, relationship

from backend.db.models.base import Base, ObjectKind, _enum
from backend.db.types import utcnow


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
