"""The Recipes page in headless Chromium: an engineer creates a recipe in the form (a
model ticked, a fixed threshold) and selects it; the Inspection page shows the active
recipe, starts from its options and sends only those changed; an operator selects
another but has no editor; a viewer sees the active recipe and no controls."""

from __future__ import annotations

import json

import httpx
import pytest

pytestmark = pytest.mark.e2e


def _sign_in(browser, server, token, page_id):
    page = browser.new_page(viewport={"width": 1400, "height": 900})
    page.goto(f"{server.base}/#{page_id}")
    page.fill("#token", token)
    page.click("#login")
    page.wait_for_selector(f"#{page_id}-page")
    return page


def test_engineer_creates_and_selects_others_follow(browser, shared_server):
    server = shared_server
    eng = server.token("e2e-recipes-eng", "engineer")
    op = server.token("e2e-recipes-op", "operator")
    viewer = server.token("e2e-recipes-viewer", "viewer")
    h = {"Authorization": f"Bearer {eng}"}
    r = httpx.post(f"{server.base}/api/models", json={"name": "wheel-rc", "kind": "2d"},
                   headers=h, timeout=60)  # fmt: skip
    assert r.status_code == 201, r.text

    page = _sign_in(browser, server, eng, "recipes")
    page.wait_for_selector("#recipe-models input[data-model='wheel-rc']")
    page.wait_for_selector("#recipe-active strong")
    assert "No active recipe" in page.inner_text("#recipe-active")
    page.fill("#recipe-name", "rims")
    page.fill("#recipe-number", "21")
    page.select_option("#recipe-policy", "top-only")
    page.select_option("#recipe-max-views", "1")
    page.fill("#recipe-threshold", "0.3")
    page.select_option("#recipe-belt", "index")
    page.check("#recipe-models input[data-model='wheel-rc']")
    page.fill("#recipe-description", "<b>rims</b> only")
    page.click("#recipe-save")
    row = page.wait_for_selector("#recipes-table tbody tr[data-name='rims']")
    text = row.inner_text()
    assert "top-only, up to 1 view(s)" in text and "threshold 0.30" in text and "wheel-rc" in text
    assert "belt index" in text
    # A bad value is refused in the form, nothing sent.
    page.fill("#recipe-threshold", "2")
    page.click("#recipe-save")
    page.wait_for_selector("#recipe-message:has-text('threshold must be a number in [0, 1]')")

    row.query_selector("button.recipe-activate").click()
    page.wait_for_selector("#recipe-active-name:has-text('rims (no. 21)')")
    got = httpx.get(f"{server.base}/api/recipes", headers=h, timeout=60).json()
    assert got["active"]["name"] == "rims" and got["active"]["description"] == "<b>rims</b> only"
    assert got["active"]["models"] == ["wheel-rc"] and got["active"]["threshold"] == 0.3

    # The Inspection page names the active recipe and starts from its options.
    page.click("a[data-page='inspection']")
    page.wait_for_selector("#insp-recipe-name:has-text('rims')")
    assert page.input_value("#insp-policy") == "top-only"
    assert page.input_value("#insp-max-views") == "1"
    assert "threshold 0.30" in page.inner_text("#insp-recipe")
    # Only what the operator changes is sent: the server takes the recipe's for the rest.
    page.select_option("#insp-policy", "naive")
    with page.expect_request(lambda q: q.url.endswith("/api/inspections")) as sent:
        page.click("#insp-once")
    assert json.loads(sent.value.post_data) == {"policy": "naive", "wait_s": 60}
    page.close()

    r = httpx.post(f"{server.base}/api/recipes", json={"name": "spare", "number": 22},
                   headers=h, timeout=60)  # fmt: skip
    assert r.status_code == 201, r.text

    # An operator selects another recipe; the editor is not theirs.
    page = _sign_in(browser, server, op, "recipes")
    spare = page.wait_for_selector("#recipes-table tbody tr[data-name='spare']")
    assert page.is_hidden("#recipe-editor")
    assert "Creating and editing recipes needs the engineer role" in page.inner_text(
        "#recipes-page"
    )
    assert page.query_selector("button.recipe-edit") is None
    spare.query_selector("button.recipe-activate").click()
    page.wait_for_selector("#recipe-active-name:has-text('spare (no. 22)')")
    page.close()

    # A viewer reads: the active recipe, no buttons.
    page = _sign_in(browser, server, viewer, "recipes")
    page.wait_for_selector("#recipes-table tbody tr[data-name='rims']")
    page.wait_for_selector("#recipe-active-name:has-text('spare')")
    assert all(not b.is_visible() for b in page.query_selector_all("button.recipe-activate"))
    assert page.is_hidden("#recipe-editor")
    page.close()
    trail = httpx.get(f"{server.base}/api/audit?kind=recipe", headers=h, timeout=60).json()
    acts = sorted((e["actor"], e["action"]) for e in trail["data"])
    assert acts == [("e2e-recipes-eng", "activate"), ("e2e-recipes-eng", "create"),
                    ("e2e-recipes-eng", "create"), ("e2e-recipes-op", "activate")]  # fmt: skip
