"""Cells known to this database."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter
from pydantic import BaseModel
from sqlalchemy import func, select

from backend.api.deps import SessionDep, ViewerUser
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
    _: ViewerUser, session: SessionDep, limit: Limit = 100, offset: Offset = 0
) -> dict[str, Any]:
    total = await session.scalar(select(func.count()).select_from(Cell))
    rows = (await session.scalars(select(Cell).order_by(Cell.id).limit(limit).offset(offset))).all()
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
