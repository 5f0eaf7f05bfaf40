"""The Audit page: an engineer finds a model's threshold change made through the API, with
who, old and new value and reason, and narrows the table by kind and entity id; other
roles do not get the page."""

from __future__ import annotations

import httpx
import pytest

pytestmark = pytest.mark.e2e


def test_audit_page_shows_a_threshold_change(browser, server):
    eng = server.token("e2e-auditor", "engineer")
    operator = server.token("e2e-op", "operator")
    h = {"Authorization": f"Bearer {eng}"}
    with httpx.Client(base_url=server.base + "/api", headers=h, timeout=60) as c:
        r = c.post("/models", json={"name": "wheel-e2e", "kind": "2d"})
        assert r.status_code == 201, r.text
        mid = r.json()["id"]
        r = c.patch(f"/models/{mid}", json={"threshold": 0.42, "reason": "<b>night</b> shift"})
        assert r.status_code == 200, r.text

    page = browser.new_page(viewport={"width": 1280, "height": 800})
    page.goto(server.base + "/#audit")
    page.fill("#token", eng)
    page.click("#login")
    page.wait_for_selector("#audit-page")
    sel = f"#audit-table tbody tr[data-kind='threshold'][data-entity='{mid}']"
    row = page.wait_for_selector(sel)
    text = row.inner_text()
    assert "e2e-auditor (engineer)" in text and "set" in text and "0.42" in text
    assert '"threshold": null' in text  # the old value (spaced between members, to wrap there)
    assert "<b>night</b> shift" in text  # the reason, as text, not markup
    assert row.query_selector("b") is None

    # Filter: kind threshold and this model's id leave only that row.
    page.select_option("#audit-kind", "threshold")
    page.fill("#audit-entity", str(mid))
    page.click("#audit-apply")
    page.wait_for_function(
        "() => document.querySelectorAll('#audit-table tbody tr[data-kind=\"model\"]').length === 0"
    )
    assert len(page.query_selector_all("#audit-table tbody tr")) == 1
    assert page.inner_text("#audit-range") == "1-1 of 1"
    # A time range before the change matches nothing.
    page.fill("#audit-until", "2001-01-01T00:00")
    page.click("#audit-apply")
    page.wait_for_selector("#audit-table tbody tr:has-text('No changes match.')")
    page.close()

    page = browser.new_page(viewport={"width": 1280, "height": 800})
    page.goto(server.base + "/#audit")
    page.fill("#token", operator)
    page.click("#login")
    page.wait_for_selector("#nav-pages a")
    assert page.query_selector("a[data-page='audit']") is None
    assert page.query_selector("#audit-page") is None
    page.close()
