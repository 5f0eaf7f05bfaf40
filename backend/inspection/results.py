"""Inspection results in the database: one row per object, written once.

An :class:`InspectionRecord` is built in memory while the object is inspected and stored
by :func:`store` in one transaction with its images, at the end (also when the inspection
fails or is cut short: a complete ``failed`` row with the reason, never a partial one).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from datetime import datetime
from typing import Any, cast

from sqlalchemy import Table, delete, func, insert, select
from sqlalchemy.ext.asyncio import AsyncSession

from backend.db.models import (
    Decision,
    Inspection,
    InspectionImage,
    InspectionInProgress,
    InspectionScene,
    InspectionStage,
)
from backend.db.session import Database, changed
from backend.db.types import utcnow
from backend.inspection.public import InspectionPublic, PickOutcome
from vision.errors import InvalidInput, NotFound

__all__ = ["PICK_OUTCOMES", "InspectionRecord", "ViewRecord", "get_image", "get_inspection",
           "inspection_public", "list_inspections", "pick_outcome", "store", "store_all",
           "stored_public"]  # fmt: skip

#: What happened to the object after the decision (:func:`pick_outcome`).
PICK_OUTCOMES = ("placed", "rejected", "not_placed", "approach", "not_picked", "not_sorted")

DECISIONS = tuple(d.value for d in Decision)
#: Where an inspection's images came from: the cell's camera, or an uploaded image.
SOURCES = ("cell", "upload")


@dataclass(frozen=True)
class ViewRecord:
    """One viewpoint's image (JPEG, contour drawn) and every model's score there."""

    viewpoint: int
    jpeg: bytes
    scores: dict[str, Any]


@dataclass(frozen=True)
class InspectionRecord:
    """Everything one inspection stores (module docstring)."""

    started_at: datetime
    finished_at: datetime
    decision: str
    reason: str
    policy: str
    model_id: int | None = None
    model_name: str | None = None
    score: float | None = None
    viewpoints: tuple[int, ...] = ()
    scores: dict[str, float] = field(default_factory=dict)
    pose: dict[str, Any] | None = None
    durations: dict[str, float] = field(default_factory=dict)
    pick: dict[str, Any] | None = None
    truth: dict[str, Any] | None = None
    duration_s: float | None = None
    """Wall time from the inspection's start to its end, seconds (the cycle time); None:
    the sum of ``durations``."""
    views: tuple[ViewRecord, ...] = ()
    source: str = "cell"
    #: The recipe the inspection ran under (:mod:`backend.recipes`), id and name then.
    recipe_id: int | None = None
    recipe_name: str | None = None

    def __post_init__(self) -> None:
        if self.decision not in DECISIONS:
            raise InvalidInput(f"decision must be one of {DECISIONS}, got {self.decision!r}")
        d = self.duration_s
        if d is not None and (
            isinstance(d, bool) or not isinstance(d, int | float) or not 0.0 <= d <= 1e6
        ):
            raise InvalidInput(f"duration_s must be in [0, 1e6] s, got {d!r}")
        if self.source not in SOURCES:
            raise InvalidInput(f"source must be one of {SOURCES}, got {self.source!r}")


async def store(
    db: Database,
    cell_id: int,
    rec: InspectionRecord,
    *,
    retention: str = "all",
    scene: bytes | None = None,
    marker_id: int | None = None,
) -> int:
    """Write the row, its stage rows, its report record (:mod:`backend.reports.blocks`), its
    images and its 3D scene recording in one transaction (all or nothing); returns the
    inspection id.

    ``retention`` (``Settings.image_retention``) says whether this decision keeps its images
    and scene (:func:`backend.reports.keeps_images`).  ``marker_id``: the inspection's
    in-progress marker (:func:`backend.inspection.recovery.begin`), deleted in the same
    transaction, so either the result is there or the marker is, never both and never
    neither.
    """
    async with db.session() as session:
        if marker_id is not None:
            gone = await session.execute(
                delete(InspectionInProgress).where(InspectionInProgress.id == marker_id)
            )
            if gone.rowcount == 0:  # type: ignore[attr-defined]
                # An earlier attempt committed and lost its answer (the link failed after
                # the commit): that row is the result; writing another would duplicate it.
                earlier = await session.scalar(
                    select(Inspection.id).where(
                        Inspection.cell_id == cell_id, Inspection.started_at == rec.started_at
                    )
                )
                if earlier is not None:
                    return int(earlier)
        (iid,) = await _write(session, cell_id, [rec], retention=retention, scene=scene)
        return iid


async def store_all(
    db: Database, cell_id: int, records: list[InspectionRecord], *, retention: str = "all"
) -> list[int]:
    """Write several records (with their stage rows, report records and images) in one
    transaction: all or none; returns their ids in order."""
    if not records:
        return []
    async with db.session() as session:
        return await _write(session, cell_id, records, retention=retention)


def _columns(cell_id: int, rec: InspectionRecord) -> dict[str, Any]:
    """The ``inspections`` column values of one record."""
    return {
        "cell_id": cell_id,
        "started_at": rec.started_at,
        "finished_at": rec.finished_at,
        "decision": Decision(rec.decision),
        "model_id": rec.model_id,
        "model_name": rec.model_name,
        "score": rec.score,
        "viewpoints_visited": list(rec.viewpoints),
        "object_pose": None if rec.pose is None else rec.pose.get("T_base_obj"),
        "duration_s": round(
            sum(rec.durations.values()) if rec.duration_s is None else rec.duration_s, 4
        ),
        "note": rec.reason[:2000],
        "policy": rec.policy,
        "reason": rec.reason,
        "durations": rec.durations,
        "scores": rec.scores,
        "pose": rec.pose,
        "pick": rec.pick,
        "truth": rec.truth,
        "source": rec.source,
        "recipe_id": rec.recipe_id,
        "recipe_name": None if rec.recipe_name is None else rec.recipe_name[:64],
    }


#: Rows per multi-row ``INSERT`` on SQLite (21 bound values each, far below its limit).
SQLITE_ROWS_PER_INSERT = 200


async def _insert_rows(session: AsyncSession, values: list[dict[str, Any]]) -> list[int]:
    """Insert ``inspections`` rows; their ids in the order of ``values``.

    PostgreSQL batches the rows and orders the returned ids itself (SQLAlchemy's
    "insertmanyvalues").  On SQLite that would be one statement per row, so the rows go in
    one multi-row ``INSERT`` per chunk: SQLite inserts them one after the other, each
    getting a rowid larger than any before it (the writer holds the database's lock), so
    the returned ids sorted are the rows' ids in order.
    """
    table = cast(Table, Inspection.__table__)
    if session.get_bind().dialect.name != "sqlite" or len(values) == 1:
        got = await session.execute(
            insert(table).returning(table.c.id, sort_by_parameter_order=True), values
        )
        return [int(i) for i in got.scalars().all()]
    ids: list[int] = []
    for k in range(0, len(values), SQLITE_ROWS_PER_INSERT):
        chunk = values[k : k + SQLITE_ROWS_PER_INSERT]
        got = await session.execute(insert(table).values(chunk).returning(table.c.id))
        ids += sorted(int(i) for i in got.scalars().all())
    return ids


async def _write(
    session: AsyncSession,
    cell_id: int,
    records: list[InspectionRecord],
    *,
    retention: str,
    scene: bytes | None = None,
) -> list[int]:
    """Add the records' rows in ``session`` (the caller's transaction); their ids in order.

    Each table gets one batched statement for all the records (the rows with ``RETURNING``
    their ids, then images, stage rows and report records), and nothing written is read
    back: storing a result costs a few statements however many records there are.
    ``scene`` (a 3D recording) belongs to a single record.
    """
    changed(session, "inspections")
    from backend.reports.blocks import append as append_records
    from backend.reports.retention import keeps_images
    from backend.reports.stages import stage_rows

    if scene is not None and len(records) != 1:
        raise ValueError(f"a scene belongs to one record, got {len(records)}")
    values = [_columns(cell_id, rec) for rec in records]
    ids = await _insert_rows(session, values)
    if len(ids) != len(records):
        raise RuntimeError(f"stored {len(ids)} inspection rows for {len(records)} records")
    now = utcnow()
    images: list[dict[str, Any]] = []
    stages: list[dict[str, Any]] = []
    for iid, rec, row in zip(ids, records, values, strict=True):
        if keeps_images(retention, rec.decision):
            images.extend(
                {"inspection_id": iid, "viewpoint": v.viewpoint, "image_jpeg": v.jpeg,
                 "scores": v.scores, "created_at": now}
                for v in rec.views
            )  # fmt: skip
        stages.extend(stage_rows(iid, row | {"decision": rec.decision}))
    if images:
        await session.execute(insert(cast(Table, InspectionImage.__table__)), images)
    if stages:
        await session.execute(insert(cast(Table, InspectionStage.__table__)), stages)
    await append_records(session, [row | {"decision": rec.decision}
                                   for row, rec in zip(values, records, strict=True)])  # fmt: skip
    if scene and keeps_images(retention, records[0].decision):
        session.add(InspectionScene(inspection_id=ids[0], scene=scene, size_bytes=len(scene)))
        await session.flush()
    return ids


def pick_outcome(pick: Any, decision: str) -> dict[str, Any]:
    """What happened to the object, from the stored pick (the console, the drill-down and
    the exports show it): ``outcome`` (one of :data:`PICK_OUTCOMES`), the ``bin`` it went
    to (or was meant for) and ``text``, a sentence for the operator.

    ``placed``: in its own bin; ``rejected``: in the reject bin (unknown, failed, or no bin
    for its part); ``not_placed``: a pick was tried and did not place it (or could not be
    planned), the reason said; ``approach``: sorting off, the arm went to the approach
    pose; ``not_picked``: sorting off and no approach; ``not_sorted``: no pick at all (the
    object was not found, or the inspection ended before)."""
    if not isinstance(pick, dict):
        return {"outcome": "not_sorted", "bin": None, "text": "not sorted"}
    b = pick.get("bin") if isinstance(pick.get("bin"), str) else None
    reason = str(pick.get("reason") or "")[:500]
    how = pick.get("how") if isinstance(pick.get("how"), str) else ""
    if not pick.get("sorted"):
        if pick.get("ok"):
            return {
                "outcome": "approach",
                "bin": None,
                "text": "sorting off: moved to the approach pose",
            }
        return {"outcome": "not_picked", "bin": None, "text": f"not picked: {reason}"}
    reject = bool(pick.get("reject")) if "reject" in pick else (b == "reject")
    if not pick.get("ok"):
        where = f" in {b}" if b else ""
        return {"outcome": "not_placed", "bin": b, "text": f"not placed{where}: {reason}"}
    if reject:
        why = {"unknown": "not a taught model", "failed": "the inspection failed"}.get(
            decision, how.rsplit("; ", 1)[-1] if how else "rejected"
        )
        return {"outcome": "rejected", "bin": b, "text": f"rejected into {b}: {why}"}
    return {"outcome": "placed", "bin": b, "text": f"placed in {b}"}


def inspection_public(row: Inspection, n_images: int | None = None) -> dict[str, Any]:
    """The API's form of a row (:class:`InspectionPublic`) as JSON values."""
    n = len(row.images) if n_images is None else n_images
    outcome = PickOutcome.model_validate(pick_outcome(row.pick, row.decision.value))
    return InspectionPublic.of(row, outcome, n).model_dump(mode="json")


#: The JSON columns of an inspection row (their stored form: tuples become lists).
_JSON_COLUMNS = ("viewpoints_visited", "durations", "scores", "pose", "pick", "truth")


def stored_public(
    iid: int, cell_id: int, rec: InspectionRecord, *, retention: str
) -> dict[str, Any]:
    """The API's form of ``rec`` as :func:`store` wrote it with id ``iid`` under
    ``retention``: what :func:`inspection_public` gives for the row read back, built from
    the same column values without reading it."""
    from backend.reports.retention import keeps_images

    values = _columns(cell_id, rec)
    for key in _JSON_COLUMNS:
        if values[key] is not None:
            values[key] = json.loads(json.dumps(values[key]))
    n = len(rec.views) if keeps_images(retention, rec.decision) else 0
    return inspection_public(Inspection(id=iid, **values), n_images=n)


async def list_inspections(
    session: AsyncSession,
    *,
    cell_id: int | None,
    limit: int,
    offset: int,
    decision: str | None = None,
    model: str | None = None,
    policy: str | None = None,
    since: datetime | None = None,
    until: datetime | None = None,
) -> tuple[list[dict[str, Any]], int]:
    """One page of inspections, newest first, with the total matching the filters."""
    if decision is not None and decision not in DECISIONS:
        raise InvalidInput(f"decision must be one of {DECISIONS}, got {decision!r}")
    if since is not None and until is not None and since > until:
        raise InvalidInput(f"since ({since.isoformat()}) is after until ({until.isoformat()})")
    conds = []
    if cell_id is not None:
        conds.append(Inspection.cell_id == cell_id)
    if decision is not None:
        conds.append(Inspection.decision == Decision(decision))
    if model is not None:
        conds.append(Inspection.model_name == model)
    if policy is not None:
        conds.append(Inspection.policy == policy)
    if since is not None:
        conds.append(Inspection.started_at >= since)
    if until is not None:
        conds.append(Inspection.started_at <= until)
    total = int(await session.scalar(select(func.count(Inspection.id)).where(*conds)) or 0)
    rows = (
        await session.scalars(
            select(Inspection)
            .where(*conds)
            .order_by(Inspection.id.desc())
            .limit(limit)
            .offset(offset)
        )
    ).all()
    counts = dict(
        (
            await session.execute(
                select(InspectionImage.inspection_id, func.count(InspectionImage.id))
                .where(InspectionImage.inspection_id.in_([r.id for r in rows]))
                .group_by(InspectionImage.inspection_id)
            )
        ).all()
    )
    return [inspection_public(r, counts.get(r.id, 0)) for r in rows], total


async def get_inspection(
    session: AsyncSession, inspection_id: int, cell_id: int | None = None
) -> Inspection:
    """The row (with its images loaded) or :class:`NotFound`."""
    from sqlalchemy.orm import selectinload

    q = (
        select(Inspection)
        .where(Inspection.id == inspection_id)
        .options(selectinload(Inspection.images))
    )
    if cell_id is not None:
        q = q.where(Inspection.cell_id == cell_id)
    row = await session.scalar(q)
    if row is None:
        raise NotFound(f"no inspection with id {inspection_id}")
    return row


async def get_image(
    session: AsyncSession, inspection_id: int, n: int, cell_id: int | None = None
) -> bytes:
    """The ``n``-th image (0-based, in the order taken) of an inspection, JPEG."""
    row = await get_inspection(session, inspection_id, cell_id)
    images = sorted(row.images, key=lambda im: im.id)
    if not 0 <= n < len(images):
        raise NotFound(f"inspection {inspection_id} has {len(images)} images; no image {n}")
    return images[n].image_jpeg
