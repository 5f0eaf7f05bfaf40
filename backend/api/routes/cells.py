"""Cells known to this database."""

from __future__ import annotations

from collections.abc import Hashable

from fastapi import APIRouter
from pydantic import BaseModel, ConfigDict
from sqlalchemy import func, select
from sqlalchemy.ext.asyncio import AsyncSession

from backend.api.deps import DatabaseDep, ReadCacheDep, ViewerUser, read_through
from backend.api.fastpath import FastRequest, Fresh
from backend.api.schemas import IsoTime, Page
from backend.api.types import Limit, Offset
from backend.db.models import Cell

router = APIRouter(prefix="/cells", tags=["cells"])


class CellPublic(BaseModel):
    """A cell as the API shows it (read from its row)."""

    model_config = ConfigDict(from_attributes=True)

    id: int
    name: str
    description: str
    created_at: IsoTime


#: What the cell list reads (its read-cache entries go when one of them is written).
CELL_TABLES = ("cells",)


def cells_key(limit: int, offset: int) -> tuple[Hashable, ...]:
    """The read-cache key of one page of the cell list."""
    return ("cells", limit, offset)


@router.get("", summary="All cells", response_model=Page[CellPublic])
async def read_cells(
    user: ViewerUser, db: DatabaseDep, cache: ReadCacheDep, limit: Limit = 100, offset: Offset = 0
) -> Page[CellPublic]:
    async def read(session: AsyncSession) -> Page[CellPublic]:
        total = await session.scalar(select(func.count()).select_from(Cell))
        q = select(Cell).order_by(Cell.id).limit(limit).offset(offset)
        rows = (await session.scalars(q)).all()
        data = [CellPublic.model_validate(c) for c in rows]
        return Page[CellPublic](data=data, count=int(total or 0))

    key = cells_key(limit, offset)
    return await read_through(cache, db, user, key, tables=CELL_TABLES, read=read)


async def fast_read_cells(req: FastRequest) -> Fresh | None:
    """:func:`read_cells` from its read-cache answer, if it has a fresh one for the role."""
    if req.role is None:
        return None
    key = cells_key(req.params["limit"], req.params["offset"])
    entry = req.runtime.read_cache.peek(key, role=req.role, topics=CELL_TABLES)
    if entry is None:
        return None
    value: Page[CellPublic] = entry.value
    return Fresh((entry,), lambda: value)
