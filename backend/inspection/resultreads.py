"""Inspection results read back and presented: one page of the list, one row, one image,
the API's form of a row and what happened to the object (:func:`pick_outcome`).

The rows are written once, by :mod:`backend.inspection.results` (which names these too).
"""

from __future__ import annotations

from datetime import datetime
from typing import Any

from sqlalchemy import func, select
from sqlalchemy.ext.asyncio import AsyncSession

from backend.db.models import Decision, Inspection, InspectionImage
from backend.inspection.public import InspectionPublic, PickOutcome
from vision.errors import InvalidInput, NotFound

__all__ = ["DECISIONS", "PICK_OUTCOMES", "get_image", "get_inspection", "inspection_public",
           "list_inspections", "pick_outcome"]  # fmt: skip

#: What happened to the object after the decision (:func:`pick_outcome`).
PICK_OUTCOMES = ("placed", "rejected", "not_placed", "approach", "not_picked", "not_sorted")

#: The decisions an inspection row may hold.
DECISIONS = tuple(d.value for d in Decision)


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
