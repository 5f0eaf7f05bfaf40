"""The application factory: REST API and console over one :class:`~backend.runtime.CellRuntime`."""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator
from pathlib import Path

from fastapi import FastAPI
from fastapi.responses import FileResponse, RedirectResponse
from fastapi.staticfiles import StaticFiles

from backend import __version__
from backend.api import FAST_READS, api_router
from backend.api.deps import install_runtime
from backend.api.docs import install_docs
from backend.api.edge import BodyGuard, document_body_limits
from backend.api.errors import install_error_handlers
from backend.api.estopfast import EStopFastPath
from backend.api.fastpath import FastReads
from backend.api.headers import SecurityHeaders, install_cors
from backend.api.limits import UrlLengthLimit
from backend.api.proxies import TrustedProxies
from backend.api.replay import install_replay
from backend.resources import resource_dir
from backend.runtime import CellRuntime, StartupError
from backend.settings import Settings

__all__ = ["WEB_DIR", "StartupError", "create_app"]

WEB_DIR: Path = resource_dir("web")


def create_app(settings: Settings | None = None, *, runtime: CellRuntime | None = None) -> FastAPI:
    """Build the FastAPI app for ``settings`` (default: from the environment).

    Without ``runtime`` the lifespan enters a :class:`CellRuntime` of ``settings`` (database,
    hardware, cell, 3D view) and exits it at shutdown; with one (already entered, e.g. by
    ``visioncell serve``) the app serves it and leaves its life cycle to the caller.  Either
    way the lifespan runs the PLC links the settings enable (``backend.plc``: OPC UA,
    Modbus TCP) over the runtime, and stops them before the runtime.
    """
    settings = settings or (runtime.settings if runtime is not None else Settings())

    @contextlib.asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        from backend.plc import plc_links

        if runtime is not None:
            install_runtime(app, runtime)
            async with plc_links(runtime):
                yield
            return
        async with CellRuntime(settings) as rt:
            install_runtime(app, rt)
            try:
                async with plc_links(rt):  # the PLC links go before the cell they drive
                    yield
            finally:
                install_runtime(app, None)

    app = FastAPI(
        title="VisionCell",
        version=__version__,
        description="Operator console API of a vision-guided robot cell. "
        'Send `Authorization: Bearer TOKEN`; errors are `{"error": code, "detail": text}`.',
        lifespan=lifespan,
        docs_url=None,
        redoc_url=None,
    )
    install_runtime(app, None, settings=settings)
    install_error_handlers(app)
    install_docs(app)
    if settings.fast_reads:  # innermost: the layers below apply to its answers too
        app.add_middleware(FastReads, routes=app.routes, reads=FAST_READS)
    # Outside the fast path: every request's body is guarded (and its sign-in checked
    # before it is read), the hot reads included.
    app.add_middleware(
        BodyGuard,
        routes=app.routes,
        json_limit=settings.max_json_body_bytes,
        upload_limit=settings.max_upload_body_bytes,
    )
    app.add_middleware(EStopFastPath)  # the E-STOP of a known token, before any framework work
    # (outside the body guard: its sign-in never stands before an E-STOP)
    app.add_middleware(UrlLengthLimit)
    install_cors(app, settings)
    app.add_middleware(SecurityHeaders, viser_port=settings.viser_port)
    # outermost: every layer, the sign-in throttle included, sees the client it resolves
    app.add_middleware(TrustedProxies, trusted=settings.trusted_proxy_networks())
    app.include_router(api_router)

    @app.get("/", include_in_schema=False)
    async def index() -> FileResponse:
        return FileResponse(WEB_DIR / "index.html", headers={"Cache-Control": "no-cache"})

    @app.get("/favicon.ico", include_in_schema=False)
    async def favicon() -> FileResponse:
        # Browsers ask for it on their own; a 404 would fill every log with noise.
        return FileResponse(
            WEB_DIR / "favicon.ico",
            media_type="image/x-icon",
            headers={"Cache-Control": "public, max-age=86400"},
        )

    @app.get("/console", include_in_schema=False)
    async def console() -> RedirectResponse:
        return RedirectResponse("/")

    install_replay(app)
    document_body_limits(
        app.routes,
        json_limit=settings.max_json_body_bytes,
        upload_limit=settings.max_upload_body_bytes,
    )
    app.mount("/static", StaticFiles(directory=WEB_DIR), name="static")
    return app
