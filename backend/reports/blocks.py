"""Report blocks: an exact, packed copy of the report columns of every inspection, in rows
per (cell, UTC hour) of at most :data:`MAX_RECORDS` records each (parts 0, 1, ..), written
in the inspection's own transaction.

Why: the reports' nearest-rank percentiles (cycle time, eleven stages, score per model)
over arbitrary filters cannot be read from a pre-aggregated histogram without losing
exactness, and per-row ``ORDER BY .. OFFSET`` queries cost a walk over up to a million
stage rows each (``benchmarks/reports.py``: seconds over 100,000 inspections).  A block
holds, for every inspection of its cell and hour, one fixed-size little-endian record
(:data:`RECORD`, 127 bytes): the start time in microseconds, the cycle time, the score,
the seconds of each stage of :data:`~backend.reports.stages.STAGES`, the number of views,
the decision and small integer ids of the model, policy and true name
(``report_names``).  A report reads the blocks of its cell and hours in one indexed query
and decodes them with one :func:`numpy.frombuffer`; filters, counts, sums and percentiles
are then computed in numpy on the very float64 values the ``inspections`` row holds, so
the answers are exact and identical on SQLite and PostgreSQL (the bytes are the same).

Consistency: :func:`append` runs inside the transaction that inserts the inspection rows
(:func:`backend.inspection.results.store`, :func:`backend.inspection.recovery.mark_interrupted`,
the bulk loader of the benchmark), so a failed write leaves no record behind and a
committed inspection always has its record.  Inspection rows are never deleted except with
their cell, and the blocks go with it (``ON DELETE CASCADE``); image retention deletes
images and scenes only.  Migration 0010 fills the blocks of the inspections stored before.

Write cost: a new record rewrites only the last part of its hour, at most
:data:`MAX_RECORDS` records (about 32 kB); a single row per hour would grow to the whole
hour's records and be rewritten on every inspection (quadratic bytes written per hour:
about 200 MB an hour for a cell on a 2 s cycle, and as many dead row versions on
PostgreSQL).

What a record does not keep: stage names outside ``STAGES`` (the inspection service times
exactly those), true names and model names beyond 64 characters (cut), more than 32,767 views.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from typing import Any

import numpy as np
from numpy.typing import NDArray
from sqlalchemy import insert, select, update
from sqlalchemy.dialects import postgresql, sqlite
from sqlalchemy.ext.asyncio import AsyncSession

from backend.db.models import Cell, ReportBlock, ReportName
from backend.reports.filters import DECISIONS, ReportFilters
from backend.reports.stages import STAGES
from vision.errors import NotFound

__all__ = ["BLOCK_S", "MAX_RECORDS", "RECORD", "Records", "append", "encode", "load", "t_us"]

#: Seconds of time one block covers (UTC hours, aligned on the epoch).
BLOCK_S = 3600
#: Most records in one part of a block (module docstring, write cost).
MAX_RECORDS = 256
_EPOCH = datetime(1970, 1, 1, tzinfo=UTC)
_US = timedelta(microseconds=1)
_NAME_LEN = 64
#: One inspection: NaN marks a missing value (no cycle time, no score, stage not timed);
#: ``model``/``truth`` are -1 when absent; ``decision`` indexes :data:`DECISIONS`.
RECORD = np.dtype(
    [("t_us", "<i8"), ("cycle", "<f8"), ("score", "<f8"), ("model", "<i4"), ("truth", "<i4"),
     ("policy", "<i4"), ("decision", "i1"), ("views", "<i2")]
    + [(f"s_{s}", "<f8") for s in STAGES]
)  # fmt: skip


def t_us(t: datetime) -> int:
    """Microseconds since 1970-01-01 UTC of the aware instant ``t`` (exact integers)."""
    if t.tzinfo is None:
        raise ValueError(f"naive datetime {t!r}: report blocks take aware UTC instants")
    return (t - _EPOCH) // _US


def _f(v: Any) -> float:
    """A stored float, or NaN for None / non-finite / negative-or-bad durations."""
    if v is None or isinstance(v, bool) or not isinstance(v, int | float):
        return math.nan
    x = float(v)
    return x if math.isfinite(x) else math.nan


def _truth_name(truth: Any) -> str | None:
    name = truth.get("name") if isinstance(truth, dict) else None
    return name[:_NAME_LEN] if isinstance(name, str) else None


def _names_of(row: dict[str, Any]) -> list[str]:
    out = [str(row["policy"])[:_NAME_LEN]]
    if row.get("model_name") is not None:
        out.append(str(row["model_name"])[:_NAME_LEN])
    t = _truth_name(row.get("truth"))
    if t is not None:
        out.append(t)
    return out


def encode(rows: Iterable[dict[str, Any]], ids: dict[str, int]) -> bytes:
    """The records of ``rows`` (inspection column values: ``started_at``, ``decision``,
    ``model_name``, ``policy``, ``duration_s``, ``score``, ``durations``,
    ``viewpoints_visited``, ``truth``) as bytes; ``ids`` maps every name to its id."""
    recs = []
    for r in rows:
        dec = getattr(r["decision"], "value", r["decision"])
        durs = r.get("durations") or {}
        stages = []
        for s in STAGES:
            v = _f(durs.get(s)) if isinstance(durs, dict) else math.nan
            stages.append(v if v >= 0 else math.nan)  # NaN >= 0 is False: stays NaN
        model = r.get("model_name")
        truth = _truth_name(r.get("truth"))
        views = r.get("viewpoints_visited")
        recs.append((
            t_us(r["started_at"]), _f(r.get("duration_s")), _f(r.get("score")),
            -1 if model is None else ids[str(model)[:_NAME_LEN]],
            -1 if truth is None else ids[truth], ids[str(r["policy"])[:_NAME_LEN]],
            DECISIONS.index(dec), min(len(views), 32767) if isinstance(views, list) else 0,
            *stages,
        ))  # fmt: skip
    return np.array(recs, dtype=RECORD).tobytes()


def _insert(session: AsyncSession, table: Any) -> Any:
    name = session.get_bind().dialect.name
    if name == "postgresql":
        return postgresql.insert(table)
    if name == "sqlite":
        return sqlite.insert(table)
    raise NotImplementedError(f"report blocks support SQLite and PostgreSQL, not {name!r}")


async def _name_ids(session: AsyncSession, names: set[str]) -> dict[str, int]:
    """The id of every name in ``names``, adding the missing ones (read first: after the
    first records of a model and policy, every name is there and one statement does)."""
    if not names:
        return {}
    sel = select(ReportName.id, ReportName.name)
    ids = {str(n): int(i) for i, n in (await session.execute(sel.where(ReportName.name.in_(names)))).all()}  # fmt: skip
    missing = sorted(names - set(ids))
    if missing:
        ins = _insert(session, ReportName.__table__)
        await session.execute(
            ins.on_conflict_do_nothing(index_elements=["name"]), [{"name": n} for n in missing]
        )
        rows = await session.execute(sel.where(ReportName.name.in_(missing)))
        ids.update({str(n): int(i) for i, n in rows.all()})
    return ids


def parts(data: bytes, n: int, new: bytes, k: int) -> list[tuple[int, bytes]]:
    """``data`` (``n`` records) with ``new`` (``k`` records) appended, cut into parts of at
    most :data:`MAX_RECORDS`: the first is the rewritten ``data``, the others new parts."""
    size = RECORD.itemsize
    room = max(0, MAX_RECORDS - n)
    out = [(n + min(room, k), bytes(data) + new[: room * size])]
    for i in range(room, k, MAX_RECORDS):
        chunk = new[i * size : (i + MAX_RECORDS) * size]
        out.append((len(chunk) // size, chunk))
    return out


async def append(session: AsyncSession, rows: Sequence[dict[str, Any]]) -> None:
    """Add the records of the inspection ``rows`` (with their ``cell_id``) to their blocks,
    in the caller's transaction (so the rows and their records commit or fail together).

    Part 0 of each hour is created empty if missing (``ON CONFLICT DO NOTHING``) and locked
    (``SELECT .. FOR UPDATE`` on PostgreSQL; SQLite's writer lock covers it) as the hour's
    lock, in (cell, hour) order so that concurrent writers cannot deadlock; then the hour's
    last part is rewritten with the new records and any that do not fit go to new parts.
    """
    if not rows:
        return
    ids = await _name_ids(session, {n for r in rows for n in _names_of(r)})
    groups: dict[tuple[int, int], list[dict[str, Any]]] = {}
    for r in rows:
        start = t_us(r["started_at"]) // (BLOCK_S * 1_000_000) * BLOCK_S
        groups.setdefault((int(r["cell_id"]), start), []).append(r)
    tb = ReportBlock.__table__
    keys = sorted(groups)
    await session.execute(
        _insert(session, tb).on_conflict_do_nothing(index_elements=["cell_id", "start_s", "part"]),
        [{"cell_id": c, "start_s": s, "part": 0, "n": 0, "data": b""} for c, s in keys],
    )
    # SQLite has one writer at a time (the insert above took its lock); PostgreSQL locks
    # rows, so part 0 is locked as the hour's lock before its last part is read.
    lock_rows = session.get_bind().dialect.name != "sqlite"
    for c, s in keys:
        hour = (tb.c.cell_id == c, tb.c.start_s == s)
        if lock_rows:
            await session.execute(select(tb.c.id).where(*hour, tb.c.part == 0).with_for_update())
        bid, part, n, data = (
            await session.execute(
                select(tb.c.id, tb.c.part, tb.c.n, tb.c.data)
                .where(*hour)
                .order_by(tb.c.part.desc())
                .limit(1)
                .with_for_update()
            )
        ).one()
        (n_last, last), *more = parts(
            data, int(n), encode(groups[(c, s)], ids), len(groups[(c, s)])
        )
        await session.execute(
            update(ReportBlock).where(ReportBlock.id == bid).values(n=n_last, data=last)
        )
        if more:
            await session.execute(
                insert(ReportBlock),
                [{"cell_id": c, "start_s": s, "part": int(part) + 1 + i, "n": k, "data": d}
                 for i, (k, d) in enumerate(more)],
            )  # fmt: skip


@dataclass(frozen=True)
class Records:
    """The records a report covers, with the names their ids stand for."""

    rec: NDArray[Any]
    """Structured array of :data:`RECORD`, shape (N,), in (cell, time-block) order."""
    names: dict[int, str]
    """Name of every id in ``rec['model']``, ``rec['policy']`` and ``rec['truth']``."""


async def load(session: AsyncSession, f: ReportFilters) -> Records:
    """The records of the inspections matching ``f``; :class:`NotFound` for an unknown cell.

    The blocks of the cell (or all cells) whose hour overlaps ``[f.start, f.end]`` are read
    in one query on ``(cell_id, start_s)``; the records are then cut to the exact instants
    and to the model, decision and policy in numpy.
    """
    tb = ReportBlock.__table__
    q = select(tb.c.data)
    if f.cell is not None:
        cell_id = await session.scalar(select(Cell.id).where(Cell.name == f.cell))
        if cell_id is None:
            raise NotFound(f"no cell named {f.cell!r}")
        q = q.where(tb.c.cell_id == cell_id)
    lo = None if f.start is None else t_us(f.start)
    hi = None if f.end is None else t_us(f.end)
    if lo is not None:
        q = q.where(tb.c.start_s >= lo // (BLOCK_S * 1_000_000) * BLOCK_S)
    if hi is not None:
        q = q.where(tb.c.start_s <= hi // 1_000_000)
    q = q.where(tb.c.n > 0).order_by(tb.c.cell_id, tb.c.start_s, tb.c.part)
    blobs = (await session.scalars(q)).all()
    names = {int(i): str(n) for i, n in (await session.execute(select(ReportName.id, ReportName.name))).all()}  # fmt: skip
    rec = np.frombuffer(b"".join(bytes(b) for b in blobs), dtype=RECORD)
    keep = np.ones(len(rec), dtype=bool)
    if lo is not None:
        keep &= rec["t_us"] >= lo
    if hi is not None:
        keep &= rec["t_us"] <= hi
    by_name = {n: i for i, n in names.items()}
    if f.model is not None:
        keep &= rec["model"] == by_name.get(f.model, -2)
    if f.policy is not None:
        keep &= rec["policy"] == by_name.get(f.policy, -2)
    if f.decision is not None:
        keep &= rec["decision"] == DECISIONS.index(f.decision)
    return Records(rec if keep.all() else rec[keep], names)


def datetime_of(us: int) -> datetime:
    """The aware UTC instant ``us`` microseconds after the epoch (inverse of :func:`t_us`)."""
    return _EPOCH + timedelta(microseconds=int(us))
