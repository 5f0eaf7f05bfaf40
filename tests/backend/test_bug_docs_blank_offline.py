"""Bug: ``/docs`` and ``/redoc`` were blank on a machine without internet: their assets
came from a CDN.  The app serves them itself (from the fastapi-offline package)."""

from __future__ import annotations

import re

import pytest

from backend.api.docs import DOCS_ASSETS, DOCS_ASSETS_URL

# Every test here only reads or is refused before anything is stored.
pytestmark = pytest.mark.shared_app

URL = re.compile(r"""(?:src|href)\s*=\s*["']([^"']+)["']|url\(\s*['"]?([^'")]+)""", re.I)


def _references(html: str) -> list[str]:
    return [a or b for a, b in URL.findall(html)]


@pytest.mark.parametrize("page", ["/docs", "/redoc"])
def test_docs_pages_load_nothing_from_outside(client, page):
    r = client.get(page)
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
    html = r.text
    assert "cdn.jsdelivr.net" not in html and "fonts.googleapis.com" not in html
    assert not re.search(r"https?://", html), re.findall(r"https?://\S+", html)
    refs = _references(html)
    assert refs, "the page references its assets"
    for ref in refs:
        assert ref.startswith("/"), ref
        asset = client.get(ref)
        assert asset.status_code == 200, ref
        assert len(asset.content) > 1000, ref


def test_every_asset_is_served_with_its_type(client):
    types = {".js": "javascript", ".css": "text/css", ".png": "image/png"}
    for name in DOCS_ASSETS:
        r = client.get(f"{DOCS_ASSETS_URL}/{name}")
        assert r.status_code == 200, name
        suffix = name[name.rfind(".") :]
        assert types[suffix] in r.headers["content-type"], (name, r.headers["content-type"])


def test_swagger_page_points_at_the_schema(client):
    html = client.get("/docs").text
    assert "/openapi.json" in html and "SwaggerUIBundle" in html
    schema = client.get("/openapi.json").json()
    assert schema["openapi"].startswith("3.")
