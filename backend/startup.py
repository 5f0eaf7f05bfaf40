"""What a cell checks and makes in its database before it starts: the schema is at the
newest Alembic revision (:func:`check_database`) and the cell has its row
(:func:`ensure_cell_row`); :class:`StartupError` says what to do when either fails.

Used by :class:`backend.runtime.CellRuntime`, which names these too.
"""

from __future__ import annotations

from sqlalchemy import select
from sqlalchemy.exc import IntegrityError

from backend.db.migrate import current_revision, head_revision
from backend.db.models import Cell as CellRow
from backend.db.session import Database, changed

__all__ = ["StartupError", "check_database", "ensure_cell_row"]


class StartupError(RuntimeError):
    """The cell cannot start; the message says what to do."""


async def check_database(db: Database) -> None:
    """Raise :class:`StartupError` unless ``db`` answers and is at the head revision."""
    try:
        rev = await current_revision(db.engine)
    except Exception as exc:
        raise StartupError(f"cannot open the database {db.url!r}: {exc}") from exc
    head = head_revision()
    if rev != head:
        raise StartupError(
            f"the database is at revision {rev!r} but this VisionCell needs {head!r}: "
            "run `visioncell db upgrade`"
        )


async def ensure_cell_row(db: Database, name: str, *, description: str = "") -> int:
    """Id of the cell row called ``name``, created if it does not exist yet (two processes
    starting together on one PostgreSQL database both get the one row)."""
    for _ in range(2):
        async with db.session() as session:
            cell_id = await session.scalar(select(CellRow.id).where(CellRow.name == name))
            if cell_id is not None:
                return int(cell_id)
        try:
            async with db.session() as session:
                row = CellRow(name=name, description=description or f"Cell {name}")
                session.add(row)
                changed(session, "cells")
                await session.flush()
                return int(row.id)
        except IntegrityError:  # another process created it meanwhile: read it again
            continue
    raise StartupError(f"cannot create or read the cell row {name!r}")
