"""Reading trained views (:mod:`backend.recognition.views`): a view's JSON form, a model's
views a page at a time, one view, and a view's stored image, thumbnail or mask."""

from __future__ import annotations

from typing import Any

from sqlalchemy import func, select
from sqlalchemy.ext.asyncio import AsyncSession
from sqlalchemy.orm import defer

from backend.db.models import TrainedView
from backend.recognition import images as im
from backend.recognition.models import get_model
from backend.recognition.public import ViewPublic
from vision.errors import NotFound


def view_public(row: TrainedView) -> dict[str, Any]:
    """JSON form of a view (:class:`ViewPublic`), with URLs of its image, thumbnail and
    mask."""
    return ViewPublic.of(row).model_dump(mode="json")


async def _view_total(session: AsyncSession, model_id: int) -> int:
    n = await session.scalar(
        select(func.count()).select_from(TrainedView).where(TrainedView.model_id == model_id)
    )
    return int(n or 0)


async def list_views(
    session: AsyncSession,
    model_id: int,
    *,
    viewpoint: int | None = None,
    limit: int = 100,
    offset: int = 0,
) -> tuple[list[TrainedView], int]:
    """A page of a model's views (image blobs not loaded) and the total."""
    await get_model(session, model_id)
    where = [TrainedView.model_id == model_id]
    if viewpoint is not None:
        where.append(TrainedView.viewpoint == viewpoint)
    total = await session.scalar(select(func.count()).select_from(TrainedView).where(*where))
    rows = await session.scalars(
        select(TrainedView)
        .where(*where)
        .options(
            defer(TrainedView.image_png),
            defer(TrainedView.mask_png),
            defer(TrainedView.features),
            defer(TrainedView.thumbnail_jpeg),
        )
        .order_by(TrainedView.id)
        .limit(limit)
        .offset(offset)
    )
    return list(rows), int(total or 0)


async def get_view(session: AsyncSession, model_id: int, view_id: int) -> TrainedView:
    """The view ``view_id`` of model ``model_id``, or :class:`NotFound`."""
    row = await session.get(TrainedView, view_id)
    if row is None or row.model_id != model_id:
        await get_model(session, model_id)
        raise NotFound(f"model {model_id} has no trained view with id {view_id}")
    return row


async def view_image(
    session: AsyncSession, model_id: int, view_id: int, *, part: str = "image"
) -> tuple[bytes, str]:
    """Bytes and media type of a view's ``image`` (PNG), ``thumb`` (JPEG) or ``mask`` (PNG)."""
    row = await get_view(session, model_id, view_id)
    if part == "thumb":
        if row.thumbnail_jpeg is None:
            rgb = im.rgb_from_png(row.image_png)
            mask = None if row.mask_png is None else im.mask_from_png(row.mask_png)
            return im.thumbnail(rgb, mask), "image/jpeg"
        return row.thumbnail_jpeg, "image/jpeg"
    if part == "mask":
        if row.mask_png is None:
            raise NotFound(f"view {view_id} has no mask (its whole image is the object)")
        return row.mask_png, "image/png"
    return row.image_png, "image/png"
