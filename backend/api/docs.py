"""API documentation pages (Swagger UI at ``/docs``, ReDoc at ``/redoc``) served offline.

FastAPI's own pages load their JavaScript and CSS from a CDN, so they are blank on a
machine without internet (a cell's usual network).  The assets come from the
``fastapi-offline`` package instead (Swagger UI 5, Apache 2.0; ReDoc, MIT; licences in that
package's metadata), served by the app under :data:`DOCS_ASSETS_URL`.  The create-app code
passes ``docs_url=None, redoc_url=None`` to FastAPI and calls :func:`install_docs`.

The one remote load left in ReDoc's bundle, the Redocly logo in its footer (an image the
page hides when it fails to load), is blanked when the bundle is served, so a browser
without network makes no request outside the cell.
"""

from __future__ import annotations

import functools
from importlib.resources import files
from pathlib import Path

from fastapi import FastAPI, Request
from fastapi.openapi.docs import (
    get_redoc_html,
    get_swagger_ui_html,
    get_swagger_ui_oauth2_redirect_html,
)
from fastapi.responses import HTMLResponse, Response
from fastapi.staticfiles import StaticFiles

__all__ = ["DOCS_ASSETS", "DOCS_ASSETS_URL", "docs_assets_dir", "install_docs"]

#: Where the assets are served.
DOCS_ASSETS_URL = "/docs-assets"
#: The files the pages load (all from :func:`docs_assets_dir`).
DOCS_ASSETS = ("swagger-ui-bundle.js", "swagger-ui.css", "redoc.standalone.js", "favicon.png")


def docs_assets_dir() -> Path:
    """The folder holding :data:`DOCS_ASSETS` (inside the installed ``fastapi_offline``)."""
    try:
        folder = Path(str(files("fastapi_offline") / "static"))
    except ModuleNotFoundError as exc:  # pragma: no cover - a declared dependency
        raise RuntimeError(
            "the API docs need the fastapi-offline package: pip install fastapi-offline"
        ) from exc
    missing = [n for n in DOCS_ASSETS if not (folder / n).is_file()]
    if missing:  # pragma: no cover - a broken install
        raise RuntimeError(f"fastapi-offline in {folder} lacks {', '.join(missing)}")
    return folder


#: Remote images inside the ReDoc bundle, replaced by an empty ``src`` when served.
_REDOC_REMOTE = (b'"https://cdn.redoc.ly/redoc/logo-mini.svg"',)


@functools.cache
def _redoc_bundle() -> bytes:
    data = (docs_assets_dir() / "redoc.standalone.js").read_bytes()
    for remote in _REDOC_REMOTE:
        data = data.replace(remote, b'""')
    return data


def install_docs(app: FastAPI, *, docs_url: str = "/docs", redoc_url: str = "/redoc") -> None:
    """Serve the assets and the two pages on ``app`` (created with ``docs_url=None``)."""
    if app.docs_url is not None or app.redoc_url is not None:
        raise ValueError("create the app with docs_url=None and redoc_url=None")

    @app.get(f"{DOCS_ASSETS_URL}/redoc.standalone.js", include_in_schema=False)
    async def redoc_bundle() -> Response:
        return Response(
            _redoc_bundle(),
            media_type="text/javascript",
            headers={"Cache-Control": "max-age=86400"},
        )

    app.mount(DOCS_ASSETS_URL, StaticFiles(directory=docs_assets_dir()), name="docs-assets")
    openapi_url = app.openapi_url or "/openapi.json"
    oauth2_url = app.swagger_ui_oauth2_redirect_url or "/docs/oauth2-redirect"

    @app.get(docs_url, include_in_schema=False)
    async def swagger_ui(request: Request) -> HTMLResponse:
        root = request.scope.get("root_path", "")
        return get_swagger_ui_html(
            openapi_url=f"{root}{openapi_url}",
            title=f"{app.title} - API",
            oauth2_redirect_url=f"{root}{oauth2_url}",
            swagger_js_url=f"{root}{DOCS_ASSETS_URL}/swagger-ui-bundle.js",
            swagger_css_url=f"{root}{DOCS_ASSETS_URL}/swagger-ui.css",
            swagger_favicon_url=f"{root}{DOCS_ASSETS_URL}/favicon.png",
            swagger_ui_parameters=app.swagger_ui_parameters,
        )

    @app.get(oauth2_url, include_in_schema=False)
    async def swagger_ui_redirect() -> HTMLResponse:
        return get_swagger_ui_oauth2_redirect_html()

    @app.get(redoc_url, include_in_schema=False)
    async def redoc(request: Request) -> HTMLResponse:
        root = request.scope.get("root_path", "")
        return get_redoc_html(
            openapi_url=f"{root}{openapi_url}",
            title=f"{app.title} - API reference",
            redoc_js_url=f"{root}{DOCS_ASSETS_URL}/redoc.standalone.js",
            redoc_favicon_url=f"{root}{DOCS_ASSETS_URL}/favicon.png",
            with_google_fonts=False,
        )
