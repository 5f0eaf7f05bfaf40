"""The filters every report takes (time range, cell, model, decision, policy), validated once.

A :class:`ReportFilters` is built by the API (query parameters) and the CLI (options) through
:func:`make_filters`, which refuses bad values with :class:`~vision.errors.InvalidInput`
quoting them; :func:`conditions` turns it into SQLAlchemy Core conditions on ``inspections``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from typing import Any

from sqlalchemy import ColumnElement, select
from sqlalchemy.ext.asyncio import AsyncSession

from backend.db.models import Cell, Decision, Inspection
from vision.errors import InvalidInput, NotFound

__all__ = [
    "DECISIONS",
    "MAX_RANGE_DAYS",
    "POLICIES",
    "ReportFilters",
    "conditions",
    "make_filters",
    "parse_time",
]

DECISIONS = tuple(d.value for d in Decision)
POLICIES = ("naive", "top-only", "two-views", "best-next")
#: Longest time range of one report, days.
MAX_RANGE_DAYS = 400
#: Timestamps outside these years are typing mistakes, not inspections.
_YEARS = (2000, 2200)
_CELL = re.compile(r"^[a-z0-9_-]{1,40}$")
_MAX_MODEL = 64


@dataclass(frozen=True)
class ReportFilters:
    """What a report covers; None everywhere means every inspection in the database."""

    start: datetime | None = None
    """Inspections started at or after this instant (UTC)."""
    end: datetime | None = None
    """Inspections started at or before this instant (UTC)."""
    cell: str | None = None
    """Cell name (a plant shares one database)."""
    model: str | None = None
    """Recognised model name."""
    decision: str | None = None
    """``recognized``, ``unknown`` or ``failed``."""
    policy: str | None = None
    """Recognition policy."""

    def echo(self) -> dict[str, Any]:
        """The filters as the API echoes them (ISO times)."""
        return {
            "from": None if self.start is None else self.start.isoformat(),
            "to": None if self.end is None else self.end.isoformat(),
            "cell": self.cell,
            "model": self.model,
            "decision": self.decision,
            "policy": self.policy,
        }


def parse_time(value: str | datetime, name: str) -> datetime:
    """An ISO-8601 instant as aware UTC (UTC when it has no offset); ``name`` is quoted on error."""
    if isinstance(value, datetime):
        t = value
    else:
        if not isinstance(value, str) or len(value) > 40:
            raise InvalidInput(f"{name} must be an ISO-8601 date-time, got {value!r}")
        try:
            t = datetime.fromisoformat(value.strip().replace("Z", "+00:00"))
        except ValueError:
            raise InvalidInput(f"{name} must be an ISO-8601 date-time, got {value!r}") from None
    try:
        t = t.replace(tzinfo=UTC) if t.tzinfo is None else t.astimezone(UTC)
    except OverflowError:  # the offset took it past year 1 or 9999: out of range too
        t = datetime.min.replace(tzinfo=UTC)
    if not _YEARS[0] <= t.year < _YEARS[1]:
        raise InvalidInput(
            f"{name} must be within the years {_YEARS[0]}..{_YEARS[1] - 1}, got {value!r}"
        )
    return t


def make_filters(
    *,
    start: str | datetime | None = None,
    end: str | datetime | None = None,
    cell: str | None = None,
    model: str | None = None,
    decision: str | None = None,
    policy: str | None = None,
) -> ReportFilters:
    """Validated filters (see :class:`ReportFilters`); raises :class:`InvalidInput` naming the value."""
    t0 = None if start is None else parse_time(start, "from")
    t1 = None if end is None else parse_time(end, "to")
    if t0 is not None and t1 is not None:
        if t0 > t1:
            raise InvalidInput(f"from ({t0.isoformat()}) is after to ({t1.isoformat()})")
        if t1 - t0 > timedelta(days=MAX_RANGE_DAYS):
            raise InvalidInput(
                f"the range from {t0.isoformat()} to {t1.isoformat()} is longer than "
                f"{MAX_RANGE_DAYS} days"
            )
    if cell is not None and not _CELL.match(cell):
        raise InvalidInput(f"cell must be a cell name (1-40 of a-z 0-9 - _), got {cell!r}")
    if model is not None and not (0 < len(model) <= _MAX_MODEL and model.isprintable()):
        raise InvalidInput(f"model must be a model name (1-{_MAX_MODEL} characters), got {model!r}")
    if decision is not None and decision not in DECISIONS:
        raise InvalidInput(f"decision must be one of {', '.join(DECISIONS)}, got {decision!r}")
    if policy is not None and policy not in POLICIES:
        raise InvalidInput(f"policy must be one of {', '.join(POLICIES)}, got {policy!r}")
    return ReportFilters(t0, t1, cell, model, decision, policy)


async def conditions(session: AsyncSession, f: ReportFilters, table: Any = None) -> list[ColumnElement[bool]]:  # fmt: skip
    """WHERE conditions for ``f`` on ``inspections`` (or ``table``, with the same filter
    columns: ``inspection_stages``); :class:`NotFound` for an unknown cell."""
    c = (Inspection.__table__ if table is None else table).c
    conds: list[ColumnElement[bool]] = []
    if f.cell is not None:
        cell_id = await session.scalar(select(Cell.id).where(Cell.name == f.cell))
        if cell_id is None:
            raise NotFound(f"no cell named {f.cell!r}")
        conds.append(c.cell_id == cell_id)
    if f.start is not None:
        conds.append(c.started_at >= f.start)
    if f.end is not None:
        conds.append(c.started_at <= f.end)
    if f.model is not None:
        conds.append(c.model_name == f.model)
    if f.decision is not None:
        conds.append(c.decision == f.decision)
    if f.policy is not None:
        conds.append(c.policy == f.policy)
    return conds
