"""Negative images: pictures of no trained object (the empty belt, other things in the
scene), stored for the automatic threshold, which counts each as an impostor (a single
model gets a threshold from them).

Uploaded ones live in ``negative_images``, shared by the plant as the models are; the
empty-belt backgrounds a teach grabs are negatives of the cell that grabbed them
(:class:`backend.recognition.teach.BackgroundStore`) and are added by the threshold keeper.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import cast

import numpy as np
from numpy.typing import NDArray
from sqlalchemy import func, select
from sqlalchemy.orm import defer

from backend import audit
from backend.db.models import NegativeImage
from backend.db.session import Database
from backend.recognition import images as im
from vision.errors import Conflict, InvalidInput, NotFound

__all__ = [
    "MAX_NEGATIVES",
    "MAX_NEGATIVES_PER_REQUEST",
    "add_negatives",
    "delete_negative",
    "list_negatives",
    "load_negatives",
    "negative_ids",
]

#: Most stored negative images (each costs one search per viewpoint per recomputation).
MAX_NEGATIVES = 200
#: Most negatives one upload adds.
MAX_NEGATIVES_PER_REQUEST = 16
#: Longest side a negative is stored with, pixels (larger ones are scaled down: a negative
#: only has to produce the features an untrained scene would).
NEGATIVE_SIDE_PX = 1024


def _shrink(rgb: NDArray[np.uint8]) -> NDArray[np.uint8]:
    import cv2

    side = max(rgb.shape[:2])
    if side <= NEGATIVE_SIDE_PX:
        return rgb
    f = NEGATIVE_SIDE_PX / side
    # uint8 in, uint8 out (the OpenCV stubs only say "array").
    return cast(NDArray[np.uint8], cv2.resize(rgb, None, fx=f, fy=f, interpolation=cv2.INTER_AREA))


def encode_negatives(images: Sequence[NDArray[np.uint8]]) -> list[tuple[bytes, int, int]]:
    """PNG bytes, width and height of each image, scaled to :data:`NEGATIVE_SIDE_PX`
    (CPU work for a worker thread)."""
    out = []
    for rgb in images:
        small = _shrink(rgb)
        out.append((im.encode_png(small), int(small.shape[1]), int(small.shape[0])))
    return out


async def add_negatives(
    db: Database,
    encoded: Sequence[tuple[bytes, int, int]],
    *,
    note: str = "",
    source: str = "upload",
    by: audit.By | None = None,
) -> list[NegativeImage]:
    """Store encoded negatives (:func:`encode_negatives`) in one transaction, all or none."""
    if not encoded:
        raise InvalidInput("no negative images given")
    if len(encoded) > MAX_NEGATIVES_PER_REQUEST:
        raise InvalidInput(
            f"at most {MAX_NEGATIVES_PER_REQUEST} negative images at once, got {len(encoded)}"
        )
    if source not in ("upload", "teach"):
        raise InvalidInput(f"source must be upload or teach, got {source!r}")
    by = by or audit.By()
    async with db.session() as session:
        have = int(await session.scalar(select(func.count()).select_from(NegativeImage)) or 0)
        if have + len(encoded) > MAX_NEGATIVES:
            raise Conflict(
                f"{have} negative images are stored; {len(encoded)} more would pass the limit "
                f"of {MAX_NEGATIVES}: delete some first"
            )
        rows = [
            NegativeImage(image_png=png, width=w, height=h, source=source, note=note[:200])
            for png, w, h in encoded
        ]
        session.add_all(rows)
        await session.flush()
        for row in rows:
            audit.record(
                session, actor=by.actor, kind="negative", entity_id=row.id, action="add",
                old=None, new={"width": row.width, "height": row.height, "source": source},
                reason=by.reason,
            )  # fmt: skip
        return rows


async def list_negatives(
    db: Database, *, limit: int = 100, offset: int = 0
) -> tuple[list[NegativeImage], int]:
    """A page of the stored negatives (no image data) and the total."""
    async with db.session() as session:
        total = int(await session.scalar(select(func.count()).select_from(NegativeImage)) or 0)
        rows = await session.scalars(
            select(NegativeImage)
            .options(defer(NegativeImage.image_png))
            .order_by(NegativeImage.id)
            .limit(limit)
            .offset(offset)
        )
        return list(rows), total


async def delete_negative(db: Database, negative_id: int, *, by: audit.By | None = None) -> None:
    """Delete one stored negative, or :class:`NotFound`."""
    by = by or audit.By()
    async with db.session() as session:
        row = await session.get(
            NegativeImage, negative_id, options=[defer(NegativeImage.image_png)]
        )
        if row is None:
            raise NotFound(f"no negative image with id {negative_id}")
        audit.record(
            session, actor=by.actor, kind="negative", entity_id=row.id, action="delete",
            old={"width": row.width, "height": row.height, "source": row.source}, new=None,
            reason=by.reason,
        )  # fmt: skip
        await session.delete(row)


async def negative_ids(db: Database) -> list[int]:
    """Ids of every stored negative (what a threshold was chosen from)."""
    async with db.session() as session:
        return list(await session.scalars(select(NegativeImage.id).order_by(NegativeImage.id)))


async def load_negatives(db: Database) -> list[NDArray[np.uint8]]:
    """Every stored negative as RGB uint8 (at most :data:`MAX_NEGATIVES`)."""
    async with db.session() as session:
        blobs = list(
            await session.scalars(
                select(NegativeImage.image_png).order_by(NegativeImage.id).limit(MAX_NEGATIVES)
            )
        )
    return [im.rgb_from_png(b) for b in blobs]
