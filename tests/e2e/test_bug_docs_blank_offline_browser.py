"""Bug: ``/docs`` and ``/redoc`` were blank without internet.  Headless Chromium loads them
with every request outside localhost blocked and sees the operations rendered."""

from __future__ import annotations

from urllib.parse import urlparse

import pytest

pytestmark = pytest.mark.e2e


def _offline_page(browser):
    context = browser.new_context()
    blocked: list[str] = []

    def route(r):
        host = urlparse(r.request.url).hostname or ""
        if host in ("127.0.0.1", "localhost"):
            r.continue_()
        else:
            blocked.append(r.request.url)
            r.abort()

    context.route("**/*", route)
    return context, context.new_page(), blocked


def test_swagger_ui_renders_offline(browser, server):
    context, page, blocked = _offline_page(browser)
    try:
        page.goto(server.base + "/docs")
        page.wait_for_selector(".opblock", timeout=30_000)
        summaries = page.locator(".opblock-summary-path").all_inner_texts()
        assert any("/api/robot/move" in s for s in summaries), summaries[:10]
        assert page.locator(".opblock").count() > 20
        assert blocked == []
    finally:
        context.close()


def test_redoc_renders_offline(browser, server):
    context, page, blocked = _offline_page(browser)
    try:
        page.goto(server.base + "/redoc")
        page.locator("h2", has_text="Latest joint state").first.wait_for(timeout=30_000)
        body = page.inner_text("body")
        assert "VisionCell" in body and "Forward kinematics" in body
        assert blocked == []
    finally:
        context.close()
