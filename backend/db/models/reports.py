"""The packed report records and the names they refer to by id."""

from __future__ import annotations

from sqlalchemy import BigInteger, ForeignKey, Integer, LargeBinary, String, UniqueConstraint
from sqlalchemy.orm import Mapped, mapped_column

from backend.db.models.base import Base


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
