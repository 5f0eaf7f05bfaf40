"""Done-when test of the console's operation pages, in headless Chromium on the simulated cell.

Teach one model from the Models page (clear the station, start teaching, place the object
through the simulator, see the views arrive), inspect twice from the Inspection page (once,
then a run of one), find both on the Reports page, open one, export the CSV and check its
rows against the database.  With ``VISIONCELL_SCREENSHOTS=DIR`` it also saves a 1280x800
screenshot of each page (``benchmarks/console_screenshots.py --docs`` sets it).
"""

from __future__ import annotations

import csv
import io
import os
import sqlite3
from pathlib import Path

import httpx
import pytest

from tests.e2e.conftest import start_server

pytestmark = pytest.mark.e2e

VIEWPORT = {"width": 1280, "height": 800}
MODEL = "gear-housing"


@pytest.fixture
def sim_server(tmp_path):
    s = start_server(
        tmp_path,
        ready_s=300.0,  # MuJoCo and the first renders start slowly on a busy machine
        VISIONCELL_DRIVER="sim",
        VISIONCELL_CAMERA="sim",
        VISIONCELL_SIM_DEMO="false",
        VISIONCELL_TIME_SCALE="5",
    )
    yield s
    s.stop()


def _shot(page, name: str) -> None:
    """Save a small PNG of the page when VISIONCELL_SCREENSHOTS names a folder."""
    folder = os.environ.get("VISIONCELL_SCREENSHOTS")
    if not folder:
        return
    from PIL import Image

    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    img = Image.open(io.BytesIO(page.screenshot(timeout=90_000)))
    img.convert("RGB").quantize(colors=128).save(out / f"{name}.png", optimize=True)


def _db_rows(server) -> list[tuple]:
    path = server.env["VISIONCELL_DATABASE_URL"].split("///", 1)[1]
    with sqlite3.connect(path) as db:
        return db.execute(
            "SELECT id, decision, model_name, policy, duration_s FROM inspections ORDER BY id"
        ).fetchall()


def _place(server, auth, name: str) -> None:
    """Put a catalogue object at the station (the belt stopped, nothing else on it)."""
    base = server.base
    objs = httpx.get(f"{base}/api/sim/objects", headers=auth, timeout=10).json()
    for o in objs["data"]:
        httpx.delete(f"{base}/api/sim/objects/{o['id']}", headers=auth, timeout=10)
    station = httpx.get(f"{base}/api/sim/conveyor", headers=auth, timeout=10).json()
    r = httpx.post(
        f"{base}/api/sim/objects",
        json={"name": name, "position_along_belt_m": station["conveyor"]["station_s_m"],
              "yaw_rad": 0.4},
        headers=auth,
        timeout=10,
    )  # fmt: skip
    assert r.status_code == 201, r.text


def test_teach_inspect_report_export(browser, sim_server):
    server = sim_server
    token = server.token("e2e-engineer", "engineer")
    auth = {"Authorization": f"Bearer {token}"}
    page = browser.new_page(viewport=VIEWPORT, accept_downloads=True)
    errors: list[str] = []
    # Errors of the console itself (the replay frame is viser's client, under its own policy).
    page.on(
        "console",
        lambda m: (
            errors.append(m.text)
            if m.type == "error" and "/replay/" not in (m.location or {}).get("url", "")
            else None
        ),
    )
    page.goto(server.base + "/#models")
    page.fill("#token", token)
    page.click("#login")
    page.wait_for_selector("#models-page")

    # -- Models: create, clear the station, teach, place the object, see the views ----------
    page.fill("#new-model-name", MODEL)
    page.select_option("#new-model-kind", "2d")
    page.click("#new-model")
    page.wait_for_selector(f'#models-table tr[data-name="{MODEL}"]')
    page.wait_for_selector("#sim-clear:not([hidden])")
    page.click("#sim-clear")
    page.wait_for_function(
        "() => document.querySelector('#teach-message').textContent.includes('station cleared')"
    )
    page.select_option("#teach-rolls", "one")  # one top view: the shortest teach
    page.click("#teach-start")
    page.wait_for_selector("#teach-place.attention", timeout=120_000)  # waits for the object
    page.select_option("#place-name", MODEL)
    page.click("#place-object")
    page.wait_for_selector("#teach-result .new-view", timeout=240_000)
    assert page.text_content("#teach-message").strip() == ""
    steps = page.locator("#teach-steps li").all_text_contents()
    assert any("view 1/" in s for s in steps), steps  # each view reported as it was taken
    page.wait_for_selector("#views-grid .view-card")
    page.wait_for_function(
        "() => [...document.querySelectorAll('#views-grid img')].some(i => i.naturalWidth > 0)"
    )
    assert page.locator(f'#models-table tr[data-name="{MODEL}"]').count() == 1
    # One top view and one model: no automatic threshold yet; the engineer sets the model's.
    page.fill("#model-threshold", "0.25")
    page.click("#model-threshold-save")
    page.wait_for_function(
        "() => document.querySelector('#model-summary').textContent.includes('Threshold: 0.250')"
    )
    _shot(page, "models")

    # -- Inspection: once (the taught object is still there), then a run of one ------------
    page.goto(server.base + "/#inspection")
    page.wait_for_selector("#inspection-page")
    page.select_option("#insp-policy", "top-only")
    page.click("#insp-once")
    page.wait_for_selector("#filmstrip .frame", timeout=120_000)
    _place(server, auth, "oil-filter")
    page.fill("#insp-count", "1")
    page.click("#insp-run")
    page.wait_for_function(
        "() => document.querySelectorAll('#filmstrip .frame').length >= 2", timeout=120_000
    )
    page.wait_for_function(
        "() => ['recognized','unknown','failed'].map(d => +document.querySelector('#count-' + d)"
        ".textContent).reduce((a, b) => a + b, 0) === 2",
        timeout=30_000,
    )
    rows = _db_rows(server)
    assert len(rows) == 2, rows
    assert rows[0][1] == "recognized" and rows[0][2] == MODEL, rows
    assert page.text_content("#live-label").startswith(f"#{rows[-1][0]} ")
    page.wait_for_function(
        "() => [...document.querySelectorAll('#filmstrip img')].every(i => i.naturalWidth > 0)"
    )
    assert "/min" in page.text_content("#throughput")
    page.wait_for_function(
        "() => [...document.querySelectorAll('#live-images img')].every(i => i.naturalWidth > 0)"
    )
    _shot(page, "inspection")

    # -- Reports: both found, one opened, the CSV matches the database ---------------------
    page.goto(server.base + "/#reports")
    page.wait_for_function("() => document.querySelector('#rep-count').textContent === '2'")
    page.wait_for_selector("#rep-table tbody tr[data-id]")
    ids = [int(v) for v in page.eval_on_selector_all(
        "#rep-table tbody tr[data-id]", "rs => rs.map(r => r.dataset.id)")]  # fmt: skip
    assert sorted(ids) == [r[0] for r in rows]
    assert page.text_content("#rep-recognized") == "1"
    _shot(page, "reports")
    page.click(f'#rep-table tr[data-id="{rows[0][0]}"]')
    page.wait_for_selector("#rep-detail:not([hidden])")
    assert f"#{rows[0][0]}" in page.text_content("#rep-detail-title")
    page.wait_for_function(
        "() => [...document.querySelectorAll('#rep-detail-views img')].some(i => i.naturalWidth > 0)"
    )
    # The scene recorded during the inspection, played back by the viser client.
    page.wait_for_function(
        "() => document.querySelector('#rep-replay-status').textContent.includes('recorded')",
        timeout=30_000,
    )
    assert page.get_attribute("#rep-replay", "src").startswith("/replay/?playbackPath=blob%3A")
    assert page.locator("#rep-detail-durations tbody tr").count() >= 3
    if os.environ.get("VISIONCELL_SCREENSHOTS"):
        page.evaluate("document.querySelector('#rep-replay').scrollIntoView()")
        page.wait_for_timeout(4000)  # the replay draws its first frames
        _shot(page, "reports-detail")
    with page.expect_download() as dl:
        page.click("#rep-export")
    text = Path(dl.value.path()).read_text()
    table = list(csv.DictReader(io.StringIO(text)))
    got = sorted((int(r["id"]), r["decision"], r["model"] or None, r["policy"]) for r in table)
    assert got == [(i, d, m, p) for i, d, m, p, _ in rows], (got, rows)
    for r, db_row in zip(sorted(table, key=lambda r: int(r["id"])), rows, strict=True):
        assert abs(float(r["duration_s"]) - db_row[4]) < 1e-3
    assert not [e for e in errors if "Content Security Policy" in e], errors
    page.close()
    # The replay page is the viser client with its own policy (same origin, no CDN).
    r = httpx.get(f"{server.base}/replay/", timeout=10)
    assert r.status_code == 200 and "wasm-unsafe-eval" in r.headers["content-security-policy"]
