"""The Models, Inspection and Reports pages follow the roles (viewers read, operators run,
engineers teach and change), the Models page uploads views and sets thresholds, and a bad
filter on the Reports page shows the API's refusal.  The ideal arm and the image folder: no
simulator needed."""

from __future__ import annotations

import httpx
import pytest

from tests.utils.models import png_bytes, textured_rgb

pytestmark = pytest.mark.e2e


def _sign_in(browser, server, token: str, page_id: str):
    page = browser.new_page(viewport={"width": 1280, "height": 800})
    page.goto(f"{server.base}/#{page_id}")
    page.fill("#token", token)
    page.click("#login")
    page.wait_for_selector(f"#{page_id}-page")
    return page


def _visible(page, sel: str) -> bool:
    return page.is_visible(sel)


def test_pages_show_each_role_only_its_controls(browser, shared_server):
    server = shared_server
    tokens = {r: server.token(f"roles-{r}", r) for r in ("viewer", "operator", "engineer")}
    seen = {}
    for role, token in tokens.items():
        page = _sign_in(browser, server, token, "models")
        page.wait_for_selector("#models-table tbody tr")
        models = (_visible(page, "#new-model-form"), _visible(page, "#teach-wizard"),
                  _visible(page, "#global-form"))  # fmt: skip
        page.goto(f"{server.base}/#inspection")
        page.wait_for_selector("#inspection-page")
        seen[role] = (*models, _visible(page, "#insp-once"), _visible(page, "#insp-run"))
        page.close()
    assert seen["viewer"] == (False, False, False, False, False)
    assert seen["operator"] == (False, False, False, True, True)
    assert seen["engineer"] == (True, True, True, True, True)


def test_models_page_uploads_views_and_sets_thresholds(browser, shared_server, tmp_path):
    server = shared_server
    token = server.token("upload-engineer", "engineer")
    auth = {"Authorization": f"Bearer {token}"}
    files = []
    for k in range(2):
        path = tmp_path / f"view{k}.png"
        path.write_bytes(png_bytes(textured_rgb(k)))
        files.append(str(path))
    page = _sign_in(browser, server, token, "models")
    page.fill("#new-model-name", "bracket-up")
    page.click("#new-model")
    page.wait_for_selector('#models-table tr[data-name="bracket-up"]')
    page.wait_for_function(
        "() => document.querySelector('#model-title').textContent.startsWith('bracket-up')"
    )
    page.set_input_files("#upload-images", files)
    page.click("#upload-start")
    page.wait_for_function(
        "() => document.querySelector('#upload-message').textContent === '2 view(s) stored'"
    )
    page.wait_for_function("() => document.querySelectorAll('#views-grid .view-card').length === 2")
    page.wait_for_function(
        "() => [...document.querySelectorAll('#views-grid img:not(.mask)')]"
        ".every(i => i.naturalWidth > 0)"
    )
    # Uploaded without masks: the page says so instead of a broken image.
    page.wait_for_function("() => document.querySelectorAll('#views-grid .fallback').length === 2")
    models = httpx.get(f"{server.base}/api/models", headers=auth, timeout=10).json()["data"]
    model = next(m for m in models if m["name"] == "bracket-up")
    assert model["views"] == 2

    # Own threshold: a bad value is refused in the page, a good one reaches the database.
    page.fill("#model-threshold", "1.5")
    page.click("#model-threshold-save")
    assert "[0, 1]" in page.text_content("#model-message")
    page.fill("#model-threshold", "0.4")
    page.click("#model-threshold-save")
    page.wait_for_function(
        "() => document.querySelector('#models-table tbody').textContent.includes('0.400')"
    )
    got = httpx.get(f"{server.base}/api/models/{model['id']}", headers=auth, timeout=10).json()
    assert got["threshold"] == 0.4
    # The global threshold by hand, with the reason kept in the audit trail.
    page.fill("#global-threshold", "0.45")
    page.fill("#global-note", "night shift glare")
    page.click("#global-save")
    page.wait_for_function(
        "() => document.querySelector('#threshold-summary').textContent.includes('0.450 (manual')"
    )
    audit = httpx.get(f"{server.base}/api/audit?kind=threshold", headers=auth, timeout=10).json()
    assert any(e["reason"] == "night shift glare" for e in audit["data"]), audit
    page.close()


def test_reports_page_shows_the_refusal_of_a_bad_range(browser, shared_server):
    server = shared_server
    token = server.token("reports-viewer", "viewer")
    page = _sign_in(browser, server, token, "reports")
    page.wait_for_function("() => document.querySelector('#rep-count').textContent !== '-'")
    assert page.text_content("#rep-count") == "0"
    assert not page.is_visible("#rep-detail")
    page.fill("#rep-from", "2026-05-02T10:00")
    page.fill("#rep-to", "2026-05-01T10:00")  # before "from"
    page.click("#rep-apply")
    page.wait_for_function("() => document.querySelector('#rep-message').textContent !== ''")
    assert "from" in page.text_content("#rep-message")
    page.close()


def test_roc_and_bins_of_the_threshold_charts(browser, shared_server):
    """The ROC the Models page draws: (FAR, TAR) for every threshold, accepting score >= t."""
    server = shared_server
    page = browser.new_page()
    page.goto(server.base + "/")
    got = page.evaluate(
        """async () => { const m = await import('/static/js/charts.js');
             return { roc: m.rocPoints([0.9, 0.8], [0.1, 0.85]),
                      bins: m.binCounts([0, 0.05, 0.5, 1, 1.2, NaN], [0, 0.25, 0.5, 0.75, 1]) }; }"""
    )
    page.close()
    assert got["roc"] == [
        [0, 0, 1],
        [0, 0.5, 0.9],
        [0.5, 0.5, 0.85],
        [0.5, 1, 0.8],
        [1, 1, 0.1],
        [1, 1, 0],
    ]
    assert got["bins"] == [2, 0, 1, 1]  # 1.0 falls in the last bin; 1.2 and NaN are dropped
