"""Inspections with their images, per-stage seconds and recorded 3D scenes."""

from __future__ import annotations

from datetime import datetime
from typing import Any

from sqlalchemy import JSON, Float, ForeignKey, Index, Integer, LargeBinary, String, Text
from sqlalchemy.orm import Mapped, mapped_column, relationship

from backend.db.models.base import Base, Decision, _enum
from backend.db.types import utcnow


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
