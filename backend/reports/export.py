"""Streamed exports of inspections: CSV and JSON lines, one row per inspection.

Rows are read in pages of :data:`PAGE_ROWS` by keyset pagination (``id > last ORDER BY id``),
each page in its own short session, so neither the process nor the database holds more than
one page and no transaction stays open while a slow client reads.  An export of more than
:data:`MAX_EXPORT_ROWS` rows is refused before the first byte (narrow the filters).
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import AsyncIterator
from typing import Any

from sqlalchemy import func, select

from backend.db.models import Cell, Inspection
from backend.db.session import Database
from backend.inspection.results import pick_outcome
from backend.reports.filters import ReportFilters, conditions
from vision.errors import InvalidInput

__all__ = ["FIELDS", "MAX_EXPORT_ROWS", "PAGE_ROWS", "check_export", "export_csv", "export_jsonl",
           "export_rows"]  # fmt: skip

#: Columns of the export, in order (the API contract), then ``viewpoints``, the pick's
#: ``bin``, ``pick`` (its outcome, :data:`backend.inspection.results.PICK_OUTCOMES`),
#: ``pick_detail`` (the sentence the console shows) and ``source`` (``cell`` or ``upload``:
#: an image sent to the recognise endpoint), then ``recipe_id`` and ``recipe`` (the recipe
#: the inspection ran under, empty for none), added at the end so that consumers reading
#: the columns by position keep working.
FIELDS = ("id", "cell", "started_at", "finished_at", "decision", "model", "score", "policy",
          "views", "duration_s", "reason", "x_mm", "y_mm", "yaw_deg", "truth_name", "viewpoints",
          "bin", "pick", "pick_detail", "source", "recipe_id", "recipe")  # fmt: skip
PAGE_ROWS = 1000
MAX_EXPORT_ROWS = 1_000_000

_I = Inspection.__table__.c


def _row(r: Any) -> dict[str, Any]:
    pose = r.pose if isinstance(r.pose, dict) else {}
    got = pose.get("position_m")
    pos: list[Any] = got if isinstance(got, list) and len(got) >= 2 else []
    ok = bool(pos)
    yaw = pose.get("yaw_rad")
    truth = r.truth if isinstance(r.truth, dict) else {}
    vps = [int(v) for v in (r.viewpoints_visited or [])]
    decision = str(getattr(r.decision, "value", r.decision))
    picked = pick_outcome(r.pick, decision)
    return {
        "id": int(r.id),
        "cell": r.cell,
        "started_at": r.started_at.isoformat(),
        "finished_at": None if r.finished_at is None else r.finished_at.isoformat(),
        "decision": str(r.decision),
        "model": r.model_name,
        "score": r.score,
        "policy": r.policy,
        "views": len(vps),
        "duration_s": r.duration_s,
        "reason": r.reason,
        "x_mm": round(float(pos[0]) * 1e3, 3) if ok else None,
        "y_mm": round(float(pos[1]) * 1e3, 3) if ok else None,
        "yaw_deg": round(math.degrees(float(yaw)), 3) if isinstance(yaw, int | float) else None,
        "truth_name": truth.get("name"),
        "viewpoints": vps,
        "bin": picked["bin"],
        "pick": picked["outcome"],
        "pick_detail": picked["text"],
        "source": getattr(r, "source", "cell"),
        "recipe_id": getattr(r, "recipe_id", None),
        "recipe": getattr(r, "recipe_name", None),
    }


async def check_export(db: Database, f: ReportFilters) -> int:
    """Number of rows the export of ``f`` has; :class:`InvalidInput` beyond the cap,
    :class:`~vision.errors.NotFound` for an unknown cell."""
    async with db.session() as s:
        conds = await conditions(s, f)
        n = int(await s.scalar(select(func.count()).select_from(Inspection).where(*conds)) or 0)
    if n > MAX_EXPORT_ROWS:
        raise InvalidInput(
            f"the export has {n} rows, more than {MAX_EXPORT_ROWS}: narrow the filters"
        )
    return n


async def export_rows(db: Database, f: ReportFilters) -> AsyncIterator[dict[str, Any]]:
    """The matching inspections in id order, one dict per row (:data:`FIELDS`), page by page."""
    last = 0
    sent = 0
    while sent < MAX_EXPORT_ROWS:
        async with db.session() as s:
            conds = await conditions(s, f)
            q = (
                select(
                    _I.id,
                    Cell.name.label("cell"),
                    _I.started_at,
                    _I.finished_at,
                    _I.decision,
                    _I.model_name,
                    _I.score,
                    _I.policy,
                    _I.viewpoints_visited,
                    _I.duration_s,
                    _I.reason,
                    _I.pose,
                    _I.truth,
                    _I.pick,
                    _I.source,
                    _I.recipe_id,
                    _I.recipe_name,
                )
                .join(Cell, Cell.id == _I.cell_id)
                .where(*conds, _I.id > last)
                .order_by(_I.id)
                .limit(min(PAGE_ROWS, MAX_EXPORT_ROWS - sent))
            )
            page = (await s.execute(q)).all()
        if not page:
            return
        for r in page:
            yield _row(r)
        sent += len(page)
        last = int(page[-1].id)


def _csv_value(v: Any) -> Any:
    if v is None:
        return ""
    if isinstance(v, list):
        return " ".join(str(x) for x in v)
    return v


async def export_csv(db: Database, f: ReportFilters) -> AsyncIterator[str]:
    """CSV text (header first), a chunk per page of rows."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(FIELDS)
    n = 0
    async for row in export_rows(db, f):
        w.writerow([_csv_value(row[k]) for k in FIELDS])
        n += 1
        if n % 200 == 0:
            yield buf.getvalue()
            buf.seek(0)
            buf.truncate()
    yield buf.getvalue()


async def export_jsonl(db: Database, f: ReportFilters) -> AsyncIterator[str]:
    """JSON lines, one object per inspection with the keys :data:`FIELDS`."""
    chunk: list[str] = []
    async for row in export_rows(db, f):
        chunk.append(json.dumps(row, separators=(",", ":")) + "\n")
        if len(chunk) >= 200:
            yield "".join(chunk)
            chunk = []
    if chunk:
        yield "".join(chunk)
