"""The console and the API docs load in headless Chromium under their Content-Security-Policy
without a single violation.  The pages only read, so the module shares one server."""

from __future__ import annotations

import pytest

pytestmark = pytest.mark.e2e

_LISTEN = """
window.__csp = [];
document.addEventListener('securitypolicyviolation',
  e => window.__csp.push(e.violatedDirective + ' ' + e.blockedURI));
"""


def _violations(page, console: list[str]) -> list[str]:
    seen = [m for m in console if "Content Security Policy" in m or "Refused to" in m]
    return seen + list(page.evaluate("window.__csp"))


def test_console_loads_without_csp_violation(browser, shared_server):
    server = shared_server
    token = server.token("csp-viewer", "engineer")
    context = browser.new_context()
    context.add_init_script(_LISTEN)
    page = context.new_page()
    console: list[str] = []
    page.on("console", lambda m: console.append(m.text))
    try:
        response = page.goto(server.base + "/")
        assert "script-src 'self';" in response.headers["content-security-policy"]
        page.wait_for_load_state("networkidle")
        # Sign in the way an operator does, so the live pages and the 3D view frame load.
        box = page.locator("input[type=password]").first
        if box.count():
            box.fill(token)
            box.press("Enter")
            page.wait_for_timeout(2000)
        assert _violations(page, console) == [], console
    finally:
        context.close()


@pytest.mark.parametrize("path", ["/docs", "/redoc"])
def test_docs_load_without_csp_violation(browser, shared_server, path):
    server = shared_server
    context = browser.new_context()
    context.add_init_script(_LISTEN)
    page = context.new_page()
    console: list[str] = []
    page.on("console", lambda m: console.append(m.text))
    try:
        page.goto(server.base + path)
        page.wait_for_load_state("networkidle")
        page.wait_for_timeout(1000)
        assert _violations(page, console) == [], console
    finally:
        context.close()


@pytest.mark.parametrize("page_id", ["inspection", "models", "recognise", "reports"])
def test_operation_pages_load_without_csp_violation(browser, shared_server, page_id):
    server = shared_server
    token = server.token(f"csp-{page_id}", "engineer")
    context = browser.new_context()
    context.add_init_script(_LISTEN)
    page = context.new_page()
    console: list[str] = []
    page.on("console", lambda m: console.append(m.text))
    try:
        page.goto(f"{server.base}/#{page_id}")
        page.fill("#token", token)
        page.click("#login")
        page.wait_for_selector(f"#{page_id}-page")
        page.wait_for_load_state("networkidle")
        page.wait_for_timeout(1000)
        assert _violations(page, console) == [], console
    finally:
        context.close()
