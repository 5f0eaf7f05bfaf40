"""Health (no token) and status (viewer)."""

from __future__ import annotations

import platform
from typing import Any

from fastapi import APIRouter
from pydantic import BaseModel

from backend import __version__
from backend.api.deps import (
    CellDep,
    DatabaseDep,
    ReadCacheDep,
    SettingsDep,
    View3DDep,
    ViewerUser,
)
from backend.db.migrate import current_revision, head_revision
from backend.db.models import Role

router = APIRouter(tags=["health"])


class HealthOut(BaseModel):
    status: str
    version: str
    viser_port: int | None


class StatusOut(BaseModel):
    """Driver, camera, database, 3D view, running jobs and library versions."""

    cell: dict[str, Any]
    driver: dict[str, Any]
    camera: dict[str, Any]
    database: dict[str, Any]
    view3d: dict[str, Any]
    jobs: dict[str, Any]
    versions: dict[str, str]


@router.get("/health", summary="Liveness; needs no token", response_model=HealthOut)
async def read_health(view: View3DDep) -> dict[str, Any]:
    return {
        "status": "ok",
        "version": __version__,
        "viser_port": view.port if view is not None else None,
    }


def _versions() -> dict[str, str]:
    import cv2
    import mujoco
    import numpy
    import viser

    return {
        "visioncell": __version__,
        "python": platform.python_version(),
        "numpy": numpy.__version__,
        "opencv": cv2.__version__,
        "mujoco": mujoco.__version__,
        "viser": viser.__version__,
    }


@router.get("/status", summary="Driver, camera, database and versions", response_model=StatusOut)
async def read_status(
    user: ViewerUser,
    settings: SettingsDep,
    db: DatabaseDep,
    cell: CellDep,
    view: View3DDep,
    cache: ReadCacheDep,
) -> dict[str, Any]:
    state = cell.driver.state
    cam = cell.camera_status()

    async def probe() -> tuple[bool, str | None]:
        ok = await db.ping()
        return ok, (await current_revision(db.engine) if ok else None)

    # Two round trips to the database, reused for the read cache's TTL (a database that
    # goes away shows within it); the cell's own state below is read on every request.
    db_ok, revision = await cache.get_or_read(
        "status-database", role=Role[user.role], tables=("alembic_version",), read=probe
    )
    return {
        "driver": {
            "name": cell.driver.name,
            "connected": state.connected,
            "moving": state.moving,
            "estopped": state.estopped,
            "fault": state.fault,
        },
        "camera": cam.as_dict(),
        "cell": {"name": cell.name, "id": cell.db_id, "estopped": cell.estopped},
        "database": {
            "url": settings.redacted_database_url(),
            "ok": db_ok,
            "revision": revision,
            "head": head_revision(),
        },
        "view3d": {
            "port": view.port if view else None,
            "clients": view.client_count() if view else 0,
            "frames_shown": view.image_updates if view else 0,
        },
        "jobs": {"running": [j.public() for j in cell.jobs.running()]},
        "versions": _versions(),
    }
