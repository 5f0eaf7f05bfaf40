"""Durable markers of work under way (an inspection, a job), so that a start-up finds what
the end of a process cut short."""

from __future__ import annotations

from datetime import datetime
from typing import Any

from sqlalchemy import JSON, ForeignKey, String
from sqlalchemy.orm import Mapped, mapped_column

from backend.db.models.base import Base
from backend.db.types import utcnow


class InspectionInProgress(Base):
    """The durable marker of an inspection that has started and not yet stored its result.

    Written (committed) before the arm moves for the inspection and deleted in the same
    transaction that writes the :class:`Inspection` row, so a marker that is still there at
    start-up names an inspection cut short by the process ending; the
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
