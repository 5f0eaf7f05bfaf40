"""Generated inspections for the reports benchmark and tests: a realistic spread over cells,
models, policies, decisions and time, bulk-inserted with SQLAlchemy Core.

Shape of the spread (seeded, so a run is reproducible): inspections every ``period_s`` on
average during two shifts a day (06:00-22:00 UTC), fewer at night; 85 % recognised, 10 %
unknown, 5 % failed; the recognised model's score near 0.8, unknown ones near 0.35; one to
three viewpoints by policy; per-stage durations like the simulated cell's; simulator truth on
about two rows in three (the decided model is the true part 95 % of the time).
"""

from __future__ import annotations

import math
import random
from collections.abc import Iterator
from datetime import UTC, datetime, timedelta
from typing import Any

from sqlalchemy import insert, select

from backend.db.models import Cell, Inspection, InspectionStage
from backend.db.session import Database
from backend.reports.blocks import append as append_records
from backend.reports.stages import STAGES, stage_rows

__all__ = ["CELLS", "MODELS", "POLICIES", "ensure_cells", "generate_rows", "insert_rows"]

CELLS = ("cell-1", "cell-2", "cell-3")
MODELS = ("wheel-a", "wheel-b", "hub-cap", "bracket-upright", "bracket-flat", "pipe-flange")
POLICIES = ("naive", "top-only", "two-views", "best-next")
_STAGE_S = {"wait": 0.8, "move": 1.2, "settle": 0.3, "acquire": 0.1, "segment": 0.05,
            "features": 0.12, "match": 0.08, "plan": 0.01, "decide": 0.002, "pose": 0.03,
            "pick": 2.5}  # fmt: skip


def generate_rows(n: int, cell_ids: list[int], *, seed: int = 0,
                  start: datetime = datetime(2026, 9, 1, tzinfo=UTC),
                  period_s: float = 30.0) -> Iterator[dict[str, Any]]:  # fmt: skip
    """``n`` inspection rows (dicts for ``insert(Inspection)``) starting at ``start``."""
    if not 0 < n <= 10_000_000:
        raise ValueError(f"n must be in 1..10^7, got {n!r}")
    rng = random.Random(seed)
    t = start
    for _ in range(n):
        hour = t.hour
        gap = rng.expovariate(1.0 / (period_s if 6 <= hour < 22 else 6 * period_s))
        t = t + timedelta(seconds=round(gap, 3) + 0.001)
        u = rng.random()
        decision = "recognized" if u < 0.85 else ("unknown" if u < 0.95 else "failed")
        policy = rng.choice(POLICIES)
        nviews = 1 if policy == "top-only" else rng.choice((1, 2, 2, 3))
        true = rng.choice(MODELS)
        model = None
        score: float | None = None
        if decision == "recognized":
            model = true if rng.random() < 0.95 else rng.choice(MODELS)
            score = round(min(1.0, max(0.0, rng.gauss(0.8, 0.08))), 4)
        elif decision == "unknown":
            score = round(min(1.0, max(0.0, rng.gauss(0.35, 0.12))), 4)
        durations = {}
        for s in STAGES:
            if s == "pick" and rng.random() < 0.5:
                continue
            scale = nviews if s in ("move", "settle", "acquire", "features", "match") else 1
            durations[s] = round(rng.lognormvariate(math.log(_STAGE_S[s] * scale), 0.3), 4)
        dur = round(sum(durations.values()), 4)
        yaw = rng.uniform(-math.pi, math.pi)
        pose = None if decision != "recognized" else {
            "position_m": [round(0.8 + rng.gauss(0, 0.01), 5), round(rng.gauss(0, 0.02), 5), 0.55],
            "yaw_rad": round(yaw, 5),
        }  # fmt: skip
        truth = None if rng.random() < 0.33 else {"name": true, "yaw_rad": round(yaw, 5)}
        yield {
            "cell_id": rng.choice(cell_ids),
            "started_at": t,
            "finished_at": t + timedelta(seconds=dur),
            "decision": decision,
            "model_name": model,
            "score": score,
            "viewpoints_visited": list(range(1, nviews + 1)),
            "duration_s": dur,
            "note": "",
            "policy": policy,
            "reason": f"{model} scored {score:.2f}" if model else decision,
            "durations": durations,
            "scores": {},
            "pose": pose,
            "truth": truth,
        }


async def ensure_cells(db: Database, names: tuple[str, ...] = CELLS) -> list[int]:
    """Ids of the cells called ``names`` (created when missing)."""
    ids = []
    async with db.session() as s:
        for name in names:
            cid = await s.scalar(select(Cell.id).where(Cell.name == name))
            if cid is None:
                row = Cell(name=name)
                s.add(row)
                await s.flush()
                cid = row.id
            ids.append(int(cid))
    return ids


async def insert_rows(db: Database, rows: Iterator[dict[str, Any]], *, chunk: int = 5000,
                      progress: Any = None) -> int:  # fmt: skip
    """Bulk-insert ``rows``, their stage rows and their report records
    (:func:`backend.reports.blocks.append`) in chunks (one transaction each); sets each
    row's ``id``; returns how many."""
    done = 0
    buf: list[dict[str, Any]] = []

    async def flush() -> None:
        nonlocal done
        async with db.session() as s:
            ids = (
                await s.scalars(
                    insert(Inspection).returning(Inspection.id, sort_by_parameter_order=True), buf
                )
            ).all()
            stages = [st for i, r in zip(ids, buf, strict=True) for st in stage_rows(i, r)]
            for k in range(0, len(stages), 20_000):
                await s.execute(insert(InspectionStage), stages[k : k + 20_000])
            for i, r in zip(ids, buf, strict=True):
                r["id"] = i
            await append_records(s, buf)
        done += len(buf)
        buf.clear()
        if progress is not None:
            progress(done)

    for r in rows:
        buf.append(r)
        if len(buf) >= chunk:
            await flush()
    if buf:
        await flush()
    return done
