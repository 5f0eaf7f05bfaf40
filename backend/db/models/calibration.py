"""Calibration sessions, their samples and the solved calibrations."""

from __future__ import annotations

from datetime import datetime
from typing import Any

from sqlalchemy import (
    JSON,
    Boolean,
    Float,
    ForeignKey,
    Index,
    Integer,
    LargeBinary,
    String,
    Text,
    UniqueConstraint,
    text,
)
from sqlalchemy.orm import Mapped, mapped_column, relationship

from backend.db.models.base import Base, CalibrationKind, _enum
from backend.db.types import utcnow


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
