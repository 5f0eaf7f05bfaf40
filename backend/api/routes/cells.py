"""Cells known to this database."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter
from sqlalchemy import select

from backend.api.deps import SessionDep, ViewerUser
from backend.db.models import Cell

router = APIRouter(prefix="/cells", tags=["cells"])


@router.get("", summary="All cells")
async def read_cells(_: ViewerUser, session: SessionDep) -> dict[str, Any]:
    rows = (await session.scalars(select(Cell).order_by(Cell.id))).all()
    data = [
        {
            "id": c.id,
            "name": c.name,
            "description": c.description,
            "created_at": c.created_at.isoformat(),
        }
        for c in rows
    ]
    return {"data": data, "count": len(data)}
