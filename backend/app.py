"""The application factory: REST API, console, and the cell's life cycle."""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import AsyncIterator
from pathlib import Path

from fastapi import FastAPI
from fastapi.responses import FileResponse, RedirectResponse
from fastapi.staticfiles import StaticFiles
from sqlalchemy import select

from backend import __version__
from backend.api import api_router
from backend.api.errors import install_error_handlers
from backend.cell import Cell
from backend.db.migrate import current_revision, head_revision
from backend.db.models import Cell as CellRow
from backend.db.session import Database
from backend.hardware import make_hardware
from backend.recognition.index import LiveIndex
from backend.settings import Settings

__all__ = ["WEB_DIR", "StartupError", "create_app"]

log = logging.getLogger(__name__)

WEB_DIR = Path(__file__).resolve().parents[1] / "web"
DEFAULT_CELL = "cell-1"


class StartupError(RuntimeError):
    """The cell cannot start; the message says what to do."""


async def _check_database(db: Database) -> None:
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


async def _ensure_cell_row(db: Database) -> None:
    async with db.session() as session:
        if await session.scalar(select(CellRow).where(CellRow.name == DEFAULT_CELL)) is None:
            session.add(CellRow(name=DEFAULT_CELL, description="The demo cell"))


async def _load_index(db: Database, settings: Settings) -> LiveIndex:
    """Build the live index of trained views from the database (once, at start-up)."""
    live = await asyncio.to_thread(
        LiveIndex,
        method=settings.recognition_method,
        max_features=settings.recognition_max_features,
    )
    report = await live.load(db)
    log.info(
        "recognition index: %d views of %d models in %.2f s (%d stale)",
        report.views,
        report.models,
        report.seconds,
        len(report.stale),
    )
    return live


def create_app(settings: Settings | None = None) -> FastAPI:
    """Build the FastAPI app for ``settings`` (default: from the environment).

    The lifespan opens the database, connects the driver, starts the camera task and the
    viser view, and shuts them down in the reverse order.
    """
    settings = settings or Settings()

    @contextlib.asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        db = Database(settings.database_url)
        app.state.db = db
        view = None
        cell = None
        try:
            await _check_database(db)
            await _ensure_cell_row(db)
            app.state.live_index = await _load_index(db, settings)
            hardware = await asyncio.to_thread(make_hardware, settings)
            app.state.sim = hardware.sim
            cell = Cell(settings, hardware.driver, hardware.camera)
            await cell.start()
            app.state.cell = cell
            if settings.view3d_enabled:
                from backend.view3d import View3D

                view = View3D(
                    cell, host=settings.viser_host, port=settings.viser_port, sim=hardware.sim
                )
                await view.start()
                app.state.view3d = view
            yield
        finally:
            app.state.cell = None
            app.state.live_index = None
            if view is not None:
                await view.stop()
            if cell is not None:
                await cell.stop()
            sim = getattr(app.state, "sim", None)
            if sim is not None:
                await asyncio.to_thread(sim.stop)
                app.state.sim = None
            await db.dispose()

    app = FastAPI(
        title="VisionCell",
        version=__version__,
        description="Operator console API of a vision-guided robot cell. "
        'Send `Authorization: Bearer TOKEN`; errors are `{"error": code, "detail": text}`.',
        lifespan=lifespan,
    )
    app.state.settings = settings
    app.state.cell = None
    app.state.view3d = None
    app.state.sim = None
    app.state.live_index = None
    install_error_handlers(app)
    app.include_router(api_router)

    @app.get("/", include_in_schema=False)
    async def index() -> FileResponse:
        return FileResponse(WEB_DIR / "index.html", headers={"Cache-Control": "no-cache"})

    @app.get("/console", include_in_schema=False)
    async def console() -> RedirectResponse:
        return RedirectResponse("/")

    app.mount("/static", StaticFiles(directory=WEB_DIR), name="static")
    return app
