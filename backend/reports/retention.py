"""Image retention: what is kept, the storage used, pruning by age or size.

``Settings.image_retention`` says whose images are stored at all (``all``, or ``failures``:
unknown and failed inspections only; :func:`keeps_images`, used where the inspection service
stores its row).  Stored images and 3D scene recordings are pruned *per inspection* (all of
its images and its scene together, so an inspection never keeps half of its views), oldest
first: by age (the inspection started more than N days ago) and by size (the oldest go until
the total is within the cap).  The inspection rows themselves are never deleted: the reports
keep counting them.

Pruning works in batches of :data:`BATCH` inspections, each in its own transaction, so it
never holds a long lock on the cell's database.  :func:`prune_loop` runs it at start-up and
then every ``Settings.image_prune_interval_s`` in the running cell.
"""

from __future__ import annotations

import asyncio
import logging
from dataclasses import dataclass
from datetime import timedelta
from typing import Any

from sqlalchemy import delete, func, literal, select, union_all
from sqlalchemy.ext.asyncio import AsyncSession

from backend.db.models import Decision, Inspection, InspectionImage, InspectionScene
from backend.db.session import Database, changed
from backend.db.types import utcnow
from backend.settings import Settings
from vision.errors import InvalidInput

__all__ = ["BATCH", "MAX_PRUNE_BYTES", "MAX_PRUNE_DAYS", "PruneResult", "keeps_images", "prune",
           "prune_loop", "storage_used"]  # fmt: skip

log = logging.getLogger(__name__)

BATCH = 500
MAX_PRUNE_DAYS = 3650
MAX_PRUNE_BYTES = 2**50


def keeps_images(retention: str, decision: str) -> bool:
    """Whether an inspection with ``decision`` stores its images under ``retention``."""
    if retention not in ("all", "failures"):
        raise InvalidInput(f"image retention must be 'all' or 'failures', got {retention!r}")
    return retention == "all" or decision != Decision.recognized.value


@dataclass(frozen=True)
class PruneResult:
    """What one prune deleted."""

    deleted_images: int = 0
    """Inspection images deleted."""
    freed_bytes: int = 0
    """Bytes of the deleted images and scenes."""
    deleted_scenes: int = 0
    """3D scene recordings deleted."""

    def __add__(self, o: PruneResult) -> PruneResult:
        return PruneResult(self.deleted_images + o.deleted_images,
                           self.freed_bytes + o.freed_bytes, self.deleted_scenes + o.deleted_scenes)  # fmt: skip

    def public(self) -> dict[str, int]:
        """The API's answer."""
        return {"deleted_images": self.deleted_images, "freed_bytes": self.freed_bytes,
                "deleted_scenes": self.deleted_scenes}  # fmt: skip


async def storage_used(session: AsyncSession) -> dict[str, int]:
    """Images and scenes stored and their bytes (``bytes`` is both together)."""
    n_img, b_img = (
        await session.execute(
            select(func.count(InspectionImage.id), func.sum(func.length(InspectionImage.image_jpeg)))
        )
    ).one()  # fmt: skip
    n_sc, b_sc = (
        await session.execute(
            select(func.count(InspectionScene.id), func.sum(InspectionScene.size_bytes))
        )
    ).one()
    b_img, b_sc = int(b_img or 0), int(b_sc or 0)
    return {"images": int(n_img), "image_bytes": b_img, "scenes": int(n_sc),
            "scene_bytes": b_sc, "bytes": b_img + b_sc}  # fmt: skip


def _stored() -> Any:
    """``(inspection_id, bytes, images, scenes)`` of every stored image and scene."""
    im = select(
        InspectionImage.inspection_id.label("iid"),
        func.length(InspectionImage.image_jpeg).label("b"),
        literal(1).label("ni"),
        literal(0).label("ns"),
    )
    sc = select(
        InspectionScene.inspection_id.label("iid"),
        InspectionScene.size_bytes.label("b"),
        literal(0).label("ni"),
        literal(1).label("ns"),
    )
    return union_all(im, sc).subquery("stored")


async def _batch(session: AsyncSession, after: int, cutoff: Any = None) -> list[tuple[int, int]]:
    u = _stored()
    q = select(u.c.iid, func.sum(u.c.b)).where(u.c.iid > after)
    if cutoff is not None:
        q = q.join(Inspection, Inspection.id == u.c.iid).where(Inspection.started_at < cutoff)
    q = q.group_by(u.c.iid).order_by(u.c.iid).limit(BATCH)
    return [(int(i), int(b or 0)) for i, b in (await session.execute(q)).all()]


async def _delete(session: AsyncSession, ids: list[int]) -> PruneResult:
    freed = 0
    rows = await session.execute(
        select(func.count(), func.sum(func.length(InspectionImage.image_jpeg))).where(
            InspectionImage.inspection_id.in_(ids)
        )
    )
    n_img, b_img = rows.one()
    n_sc, b_sc = (
        await session.execute(
            select(func.count(), func.sum(InspectionScene.size_bytes)).where(
                InspectionScene.inspection_id.in_(ids)
            )
        )
    ).one()
    await session.execute(delete(InspectionImage).where(InspectionImage.inspection_id.in_(ids)))
    changed(session, "inspection_images")
    await session.execute(delete(InspectionScene).where(InspectionScene.inspection_id.in_(ids)))
    freed = int(b_img or 0) + int(b_sc or 0)
    return PruneResult(int(n_img), freed, int(n_sc))


async def prune(db: Database, *, older_than_days: int | None = None,
                max_bytes: int | None = None) -> PruneResult:  # fmt: skip
    """Delete the images and scenes of inspections started more than ``older_than_days`` ago,
    then those of the oldest inspections until at most ``max_bytes`` remain (module docstring).
    None skips a rule; 0 deletes everything it covers."""
    if older_than_days is not None and not (
        isinstance(older_than_days, int) and 0 <= older_than_days <= MAX_PRUNE_DAYS
    ):
        raise InvalidInput(f"older_than_days must be in 0..{MAX_PRUNE_DAYS}, got {older_than_days!r}")  # fmt: skip
    if max_bytes is not None and not (isinstance(max_bytes, int) and 0 <= max_bytes <= MAX_PRUNE_BYTES):  # fmt: skip
        raise InvalidInput(f"max_bytes must be in 0..{MAX_PRUNE_BYTES}, got {max_bytes!r}")
    total = PruneResult()
    if older_than_days is not None:
        cutoff = utcnow() - timedelta(days=older_than_days)
        while True:
            async with db.session() as s:
                ids = [i for i, _ in await _batch(s, 0, cutoff)]
                if not ids:
                    break
                total += await _delete(s, ids)
    if max_bytes is not None:
        async with db.session() as s:
            excess = (await storage_used(s))["bytes"] - max_bytes
        after = 0
        while excess > 0:
            async with db.session() as s:
                batch = await _batch(s, after)
                if not batch:
                    break
                ids = []
                for i, b in batch:
                    if excess <= 0:
                        break
                    ids.append(i)
                    excess -= b
                after = batch[-1][0]
                total += await _delete(s, ids)
    if total.freed_bytes:
        log.info("pruned %d images and %d scenes (%d bytes)", total.deleted_images,
                 total.deleted_scenes, total.freed_bytes)  # fmt: skip
    return total


async def prune_loop(db: Database, settings: Settings) -> None:
    """Prune by the settings' limits now and then every ``image_prune_interval_s`` (never
    raises: a failed prune is logged and retried at the next period)."""
    while True:
        try:
            await prune(db, older_than_days=settings.image_max_age_days,
                        max_bytes=settings.image_max_bytes)  # fmt: skip
        except asyncio.CancelledError:
            raise
        except Exception:
            log.exception("the automatic image prune failed; retrying in %.0f s",
                          settings.image_prune_interval_s)  # fmt: skip
        await asyncio.sleep(settings.image_prune_interval_s)
