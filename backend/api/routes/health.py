"""Health (no token) and status (viewer)."""

from __future__ import annotations

import platform
from typing import Any

from fastapi import APIRouter
from pydantic import BaseModel, Field

from backend import __version__
from backend.api.deps import (
    CellDep,
    DatabaseDep,
    ReadCacheDep,
    SettingsDep,
    View3DDep,
    ViewerUser,
)
from backend.api.fastpath import FastRequest, Fresh
from backend.api.routes.camera import CameraStatusOut
from backend.api.schemas import JobPublic
from backend.cell import Cell
from backend.db.migrate import current_revision, head_revision
from backend.db.models import Role
from backend.settings import Settings

router = APIRouter(tags=["health"])


class HealthOut(BaseModel):
    status: str
    version: str
    viser_port: int | None


class CellStatusOut(BaseModel):
    name: str
    id: int | None = Field(description="The cell's row id (None until it is registered)")
    estopped: bool = Field(description="The cell-wide emergency stop holds")


class DriverStatusOut(BaseModel):
    name: str = Field(description="sim, serial or ideal")
    connected: bool
    moving: bool
    estopped: bool
    fault: str = Field(description="The driver's fault, empty when healthy")


class CameraHealthOut(CameraStatusOut):
    retries: int = Field(description="Failed attempts in the current outage (0 when healthy)")


class DatabaseStatusOut(BaseModel):
    url: str = Field(description="The database URL without its password")
    ok: bool = Field(description="The database answered")
    revision: str | None = Field(description="Its schema revision (None: not reachable)")
    head: str | None = Field(description="The newest revision this VisionCell knows")


class View3DStatusOut(BaseModel):
    port: int | None = Field(description="The 3D view's port (None: not running)")
    clients: int = Field(description="Browsers connected to it")
    frames_shown: int = Field(description="Camera images it has shown")


class JobsStatusOut(BaseModel):
    running: list[JobPublic]


class StatusOut(BaseModel):
    """Driver, camera, database, 3D view, running jobs and library versions."""

    cell: CellStatusOut
    driver: DriverStatusOut
    camera: CameraHealthOut
    database: DatabaseStatusOut
    view3d: View3DStatusOut
    jobs: JobsStatusOut
    versions: dict[str, str] = Field(
        description="Version of visioncell, python, numpy, opencv, mujoco and viser"
    )


def health_answer(view: Any) -> dict[str, Any]:
    """The liveness answer (``view``: the 3D view or None)."""
    return {
        "status": "ok",
        "version": __version__,
        "viser_port": view.port if view is not None else None,
    }


@router.get("/health", summary="Liveness; needs no token", response_model=HealthOut)
async def read_health(view: View3DDep) -> dict[str, Any]:
    return health_answer(view)


async def fast_read_health(req: FastRequest) -> Fresh | None:
    """:func:`read_health` of the running cell."""
    return Fresh.of_content(health_answer(req.runtime.view3d))


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


#: The read-cache key and tables of the status's database probe.
STATUS_DB_KEY = "status-database"
STATUS_DB_TABLES = ("alembic_version",)


def status_answer(
    settings: Settings, cell: Cell, view: Any, db_ok: bool, revision: str | None
) -> dict[str, Any]:
    """The status answer from the database probe (``db_ok``, ``revision``) and the cell's
    state now."""
    state = cell.driver.state
    cam = cell.camera_status()
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


@router.get("/status", summary="Driver, camera, database and versions", response_model=StatusOut)
async def read_status(
    user: ViewerUser,
    settings: SettingsDep,
    db: DatabaseDep,
    cell: CellDep,
    view: View3DDep,
    cache: ReadCacheDep,
) -> dict[str, Any]:
    async def probe() -> tuple[bool, str | None]:
        ok = await db.ping()
        return ok, (await current_revision(db.engine) if ok else None)

    # Two round trips to the database, reused for the read cache's TTL (a database that
    # goes away shows within it); the cell's own state is read on every request.
    db_ok, revision = await cache.get_or_read(
        STATUS_DB_KEY, role=Role[user.role], topics=STATUS_DB_TABLES, read=probe
    )
    return status_answer(settings, cell, view, db_ok, revision)


async def fast_read_status(req: FastRequest) -> Fresh | None:
    """:func:`read_status` when the database probe's read-cache entry is fresh for the
    role (the cell's state changes all the time: its answer is kept while equal)."""
    if req.role is None:
        return None
    rt = req.runtime
    entry = rt.read_cache.peek(STATUS_DB_KEY, role=req.role, topics=STATUS_DB_TABLES)
    if entry is None:
        return None
    db_ok, revision = entry.value
    return Fresh.of_content(status_answer(req.settings, rt.cell, rt.view3d, db_ok, revision))
