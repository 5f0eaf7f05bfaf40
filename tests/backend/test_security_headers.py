"""Security headers on the console and the API; CORS closed unless configured."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from tests.utils.factories import make_settings, migrate

# Every test here only reads or is refused before anything is stored.
pytestmark = pytest.mark.shared_app


def test_console_and_api_carry_the_security_headers(client, settings):
    for path in ("/", "/api/health", "/static/js/main.js", "/api/robot/state"):
        r = client.get(path)
        assert r.headers["x-content-type-options"] == "nosniff", path
        assert r.headers["referrer-policy"] == "no-referrer", path
        assert r.headers["x-frame-options"] == "SAMEORIGIN", path
        csp = r.headers["content-security-policy"]
        assert "script-src 'self';" in csp and "unsafe-inline" not in csp, path
        assert "frame-ancestors 'self'" in csp, path
        # The embedded 3D view: same host as the page, viser's port.
        assert f"frame-src 'self' http://testserver:{settings.viser_port};" in csp, path


def test_docs_have_their_own_policy(client):
    for path in ("/docs", "/redoc"):
        r = client.get(path)
        assert r.status_code == 200
        csp = r.headers["content-security-policy"]
        assert "script-src 'self' 'unsafe-inline'" in csp and "https:" not in csp


def test_forged_host_cannot_inject_directives(client):
    r = client.get("/", headers={"Host": "evil; script-src *"})
    csp = r.headers["content-security-policy"]
    assert "evil" not in csp and "script-src *" not in csp


def test_index_has_no_inline_script_style_or_handler():
    import re

    from backend.app import WEB_DIR

    html = (WEB_DIR / "index.html").read_text()
    assert not re.search(r"<script(?![^>]*\bsrc=)[^>]*>", html)
    assert "<style" not in html and not re.search(r"\sstyle\s*=", html)
    assert not re.search(r"\son[a-z]+\s*=", html)
    for js in (WEB_DIR / "js").rglob("*.js"):
        text = js.read_text()
        assert not re.search(r"""\son[a-z]+\s*=\s*["']""", text), js  # no inline handlers
        assert "style=" not in text, js


def _preflight(client: TestClient, origin: str):
    return client.options(
        "/api/robot/state",
        headers={
            "Origin": origin,
            "Access-Control-Request-Method": "GET",
            "Access-Control-Request-Headers": "authorization",
        },
    )


def test_cors_is_closed_by_default(client):
    r = _preflight(client, "https://evil.example")
    assert r.status_code >= 400
    assert "access-control-allow-origin" not in r.headers
    r = client.get("/api/health", headers={"Origin": "https://evil.example"})
    assert "access-control-allow-origin" not in r.headers


def test_cors_allows_a_configured_origin_only(tmp_path):
    s = make_settings(tmp_path, cors_origins=["https://hmi.plant.local"])
    migrate(s)
    with TestClient(create_app(s)) as client:
        r = _preflight(client, "https://hmi.plant.local")
        assert r.status_code == 200
        assert r.headers["access-control-allow-origin"] == "https://hmi.plant.local"
        assert "authorization" in r.headers["access-control-allow-headers"].lower()
        r = _preflight(client, "https://evil.example")
        assert r.headers.get("access-control-allow-origin") != "https://evil.example"


@pytest.mark.parametrize(
    "origins", [["*"], ["hmi.plant.local"], ["https://hmi/x"], ["javascript:alert(1)"]]
)
def test_cors_origins_are_validated(tmp_path, origins):
    with pytest.raises(ValueError, match="cors_origins"):
        make_settings(tmp_path, cors_origins=origins)


def test_replay_page_is_the_viser_client_with_its_own_policy(client):
    r = client.get("/replay/")
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
    csp = r.headers["content-security-policy"]
    # Its inline bootstrap and WebAssembly are allowed; nothing from another origin.
    assert "'unsafe-inline'" in csp and "'wasm-unsafe-eval'" in csp
    assert "https:" not in csp and "http:" not in csp and "*" not in csp
    assert "frame-ancestors 'self'" in csp
    assert client.get("/", headers={}).headers["content-security-policy"].count("wasm") == 0
