"""The console's smaller faults, checked in one browser session each role:

- ``/favicon.ico`` was a 404 (now a small icon from ``web/``);
- a user without the role saw read-only pages with no hint (now: the role it takes and
  how to get a token); *Inspect once* with nothing taught named an API path (now: a link
  to the Models page);
- job lines read "done (viewpoint 2)", the last progress step (now: what came of the job);
- only the decided model's score bar was shown (now every taught model's, on the
  Inspection page and in the Reports drill-down);
- the drill-down opened below the long lists, off screen (now it scrolls into view);
- the audit table broke words ("mode l", "startu p");
- the teach wizard's success message was red;
- at 1280 px the 3D view had a third of the page, half of it under the view's panel.
"""

from __future__ import annotations

import asyncio
import threading
from datetime import UTC, datetime, timedelta

import httpx
import pytest

from backend.db.session import Database
from backend.inspection.results import InspectionRecord, ViewRecord, store
from benchmarks.reports_data import ensure_cells
from tests.e2e.conftest import start_server

pytestmark = pytest.mark.e2e


@pytest.fixture
def ui_server(tmp_path):
    s = start_server(tmp_path, ready_s=300.0)  # a start on a loaded machine (a bound only)
    yield s
    s.stop()


TIMEOUT = 30.0
MODELS = ("a-wheel", "b-gear", "c-valve")
ROWS = 25  # more than the Reports table's page: the drill-down opens below a long page


def _sign_in(browser, server, token: str, page_id: str):
    page = browser.new_page(viewport={"width": 1280, "height": 800})
    page.goto(f"{server.base}/#{page_id}")
    page.fill("#token", token)
    page.click("#login")
    page.wait_for_selector(f"#{page_id}-page")
    return page


def _seed(url: str) -> None:
    """Inspections as the cell stores them, each with the decided model's score only."""

    async def run() -> None:
        db = Database(url)
        try:
            (cid,) = await ensure_cells(db, ("cell-1",))
            t0 = datetime.now(UTC) - timedelta(minutes=30)
            for k in range(ROWS):
                t = t0 + timedelta(seconds=10 * k)
                rec = InspectionRecord(
                    started_at=t, finished_at=t + timedelta(seconds=2), decision="recognized",
                    reason="a-wheel scored 0.91", policy="two-views", model_name="a-wheel",
                    score=0.91, viewpoints=(1,), scores={"a-wheel": 0.91},
                    durations={"total": 2.0}, views=(ViewRecord(1, b"\xff\xd8" + bytes(200), {}),),
                )  # fmt: skip
                await store(db, cid, rec)
        finally:
            await db.dispose()

    # Playwright's sync API runs an event loop in this thread: the seeding gets its own.
    errors: list[BaseException] = []

    def seed() -> None:
        try:
            asyncio.run(run())
        except BaseException as exc:  # re-raised below, in the test's thread
            errors.append(exc)

    worker = threading.Thread(target=seed)
    worker.start()
    worker.join(TIMEOUT * 4)
    assert not worker.is_alive(), "seeding the inspections hung"
    if errors:
        raise errors[0]


def test_the_small_things(browser, ui_server):
    server = ui_server
    # -- the favicon ---------------------------------------------------------------------
    r = httpx.get(f"{server.base}/favicon.ico", timeout=TIMEOUT)
    assert r.status_code == 200 and r.headers["content-type"] == "image/x-icon"
    assert r.content[:4] == b"\x00\x00\x01\x00"  # an ICO file

    # -- a missing role: the next step is named --------------------------------------------
    operator = server.token("small-operator", "operator")
    page = _sign_in(browser, server, operator, "inspection")
    page.click("#insp-once")
    page.wait_for_selector("#insp-teach-link")
    text = page.text_content("#insp-message")
    assert "teach a model first on the Models page" in text and "POST /api" not in text
    assert "engineer role" in text  # an operator cannot teach
    page.click("#insp-teach-link")
    page.wait_for_selector("#models-page")
    hint = page.wait_for_selector(".role-hint[data-needs='engineer']")
    assert "you are signed in as operator" in hint.text_content()
    assert "visioncell user add NAME --role engineer" in hint.text_content()
    page.close()
    viewer = server.token("small-viewer", "viewer")
    page = _sign_in(browser, server, viewer, "inspection")
    assert "needs the operator role" in page.wait_for_selector(".role-hint").text_content()
    page.close()

    # -- every model's score, the drill-down in view, job lines, audit, colours, layout ---
    engineer = server.token("small-engineer", "engineer")
    auth = {"Authorization": f"Bearer {engineer}"}
    for name in MODELS:
        r = httpx.post(f"{server.base}/api/models", json={"name": name, "kind": "2d"},
                       headers=auth, timeout=TIMEOUT)  # fmt: skip
        assert r.status_code == 201, r.text
    _seed(server.env["VISIONCELL_DATABASE_URL"])
    bars_px = f"{len(MODELS) * 22 + 26}px"  # charts.js: one 22 px row per bar

    page = _sign_in(browser, server, engineer, "inspection")
    page.wait_for_function(
        f"() => document.querySelector('#live-scores').style.height === '{bars_px}'"
    )

    page.goto(f"{server.base}/#reports")
    page.wait_for_selector("#rep-table tbody tr[data-id]")
    page.evaluate("() => window.scrollTo(0, 0)")
    page.click("#rep-table tbody tr[data-id]:last-child")
    page.wait_for_selector("#rep-detail:not([hidden])")
    page.wait_for_function(
        "() => { const t = document.querySelector('#rep-detail').getBoundingClientRect().top;"
        " return t >= 0 && t < window.innerHeight - 100; }"  # its start on screen
    )
    page.wait_for_function(
        f"() => document.querySelector('#rep-detail-scores').style.height === '{bars_px}'"
    )

    details = page.evaluate(
        """async () => {
          const { jobDetail } = await import("/static/js/pages/cell.js");
          return [
            jobDetail({ kind: "inspect", state: "done", message: "viewpoint 2",
                        result: { inspection: { id: 7, decision: "recognized", model: "a-wheel", score: 0.912 } } }),
            jobDetail({ kind: "teach", state: "done", message: "choosing the threshold",
                        result: { views: [{}, {}, {}], model: { name: "b-gear" } } }),
            jobDetail({ kind: "inspection-run", state: "done", message: "2 inspected: recognized a-wheel",
                        result: { inspected: 2, decisions: { recognized: 1, unknown: 1 } } }),
            jobDetail({ kind: "inspect", state: "running", message: "viewpoint 2" }),
            jobDetail({ kind: "inspect", state: "failed", message: "viewpoint 2",
                        error: { error: "conflict", detail: "the arm is busy" } }),
          ];
        }"""
    )
    assert details == [
        "inspection #7: recognized a-wheel 0.91",
        "3 view(s) stored for b-gear",
        "2 inspected: 1 recognized, 1 unknown",
        "viewpoint 2",
        "the arm is busy",
    ]

    page.goto(f"{server.base}/#audit")
    page.wait_for_selector("#audit-table tbody tr[data-kind='model']")
    row = "#audit-table tbody tr[data-kind='model']"
    assert (
        page.eval_on_selector(f"{row} td:nth-child(3)", "td => getComputedStyle(td).whiteSpace")
        == "nowrap"
    )
    assert '"name": "' in page.text_content(f"{row} td.audit-value:nth-child(7)")
    # "model", the actor and the time each on one line (no word broken across lines).
    lines = page.eval_on_selector(
        row,
        "tr => [...tr.querySelectorAll('td')].slice(0, 5).map(td => {"
        " const r = document.createRange(); r.selectNodeContents(td);"
        " return new Set([...r.getClientRects()].map(x => Math.round(x.top))).size; })",
    )
    assert lines == [1, 1, 1, 1, 1], lines

    colour = page.evaluate(
        "() => { const p = document.createElement('p'); p.className = 'error ok';"
        " document.body.append(p); const c = getComputedStyle(p).color; p.remove(); return c; }"
    )
    assert colour == "rgb(21, 128, 61)"  # --ok, not --red

    page.goto(f"{server.base}/#cell")
    page.wait_for_selector("#view3d")
    width = page.eval_on_selector("#view3d", "f => f.getBoundingClientRect().width")
    assert width > 0.6 * 1280, width  # two columns' width, not a third of the page
    page.close()
