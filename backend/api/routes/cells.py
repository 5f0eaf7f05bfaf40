"""Cells known to this database."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter
from pydantic import BaseModel
from sqlalchemy import func, select
from sqlalchemy.ext.asyncio import AsyncSession

from backend.api.deps import DatabaseDep, ReadCacheDep, ViewerUser, read_through
from backend.api.schemas import Page
from backend.api.types import Limit, Offset
from backend.db.models import Cell

router = APIRouter(prefix="/cells", tags=["cells"])


class CellPublic(BaseModel):
    id: int
    name: str
    description: str
    created_at: str


@router.get("", summary="All cells", response_model=Page[CellPublic])
async def read_cells(
    user: ViewerUser, db: DatabaseDep, cache: ReadCacheDep, limit: Limit = 100, offset: Offset = 0
) -> dict[str, Any]:
    async def read(session: AsyncSession) -> dict[str, Any]:
        total = await session.scalar(select(func.count()).select_from(Cell))
        q = select(Cell).order_by(Cell.id).limit(limit).offset(offset)
        rows = (await session.scalars(q)).all()
        data = [
            {
                "id": c.id,
                "name": c.name,
                "description": c.description,
                "created_at": c.created_at.isoformat(),
            }
            for c in rows
        ]
        return {"data": data, "count": int(total or 0)}

    key = ("cells", limit, offset)
    return await read_through(cache, db, user, key, tables=("cells",), read=read)
