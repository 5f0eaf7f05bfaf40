"""The Calibration tab: sessions, their status, report plots, and Activate for engineers."""

from __future__ import annotations

import httpx
import pytest

from tests.utils.calibration import write_synthetic_folder

pytestmark = pytest.mark.e2e


def test_calibration_tab_lists_sessions_shows_reports_and_activates(browser, server, tmp_path):
    folder = write_synthetic_folder(tmp_path / "views", n=6)
    eng = server.token("e2e-engineer", "engineer")
    viewer = server.token("e2e-viewer", "viewer")
    h = {"Authorization": f"Bearer {eng}"}
    with httpx.Client(base_url=server.base + "/api/calibration", headers=h, timeout=120) as c:
        r = c.post(
            "/sessions",
            json={"kind": "intrinsic", "board": {"cols": 9, "rows": 6, "square_mm": 30}},
        )
        sid = r.json()["session"]["id"]
        files = [("images", (f.name, f.read_bytes(), "image/png")) for f in folder.files]
        assert c.post(f"/sessions/{sid}/samples", files=files).status_code == 201
        r = c.post(f"/sessions/{sid}/solve?wait=true", json={})
        assert r.status_code == 200, r.text
        cid = r.json()["job"]["result"]["calibration_id"]

    page = browser.new_page(viewport={"width": 1400, "height": 1000})
    page.goto(server.base + "/")
    page.fill("#token", viewer)
    page.click("#login")
    page.click("a[data-page='calibration']")
    page.wait_for_selector("#calibration-page:not([hidden])")
    row = page.wait_for_selector(f"#calib-sessions tbody tr[data-id='{sid}']")
    assert "solved" in row.inner_text() and "6 / 7" in row.inner_text()
    row.click()
    page.wait_for_selector(f"#calib-calibrations tbody tr:has-text('#{cid}')")
    assert page.query_selector(".activate") is None  # viewers cannot activate
    assert not page.is_visible("#calib-auto-start")  # nor start an automatic run
    assert "rejected" in page.inner_text("#calib-samples")
    page.close()

    page = browser.new_page(viewport={"width": 1400, "height": 1000})
    page.goto(server.base + "/#calibration")
    page.fill("#token", eng)
    page.click("#login")
    page.wait_for_selector("#calibration-page:not([hidden])")
    page.click(f"#calib-sessions tbody tr[data-id='{sid}']")
    page.click(f"#calib-calibrations tbody tr:has-text('#{cid}') >> text=Report")
    page.wait_for_function(
        "() => document.querySelector('#plot-residuals').src.startsWith('blob:')"
    )
    page.wait_for_function("() => document.querySelector('#plot-coverage').naturalWidth > 200")
    assert "RMS" in page.inner_text("#calib-summary") and "fx =" in page.inner_text(
        "#calib-summary"
    )
    page.click(f".activate[data-id='{cid}']")
    page.wait_for_selector(f"#calib-sessions tbody tr[data-id='{sid}'] .status-active")
    # The sessions table and the "Active" line refresh from two requests: wait for both.
    page.wait_for_function(
        "(want) => document.querySelector('#calib-active').textContent.includes(want)",
        arg=f"intrinsic: #{cid}",
    )
    # Start of an automatic run: this server has no simulator and no board pattern was
    # given, so the API's reason is shown (a full run is in tests/backend/test_calibration_auto.py).
    page.click("#calib-auto-start")
    page.wait_for_function(
        "() => document.querySelector('#calib-auto-status').textContent.includes('pattern')"
    )
    assert page.is_enabled("#calib-auto-start")
    page.close()
