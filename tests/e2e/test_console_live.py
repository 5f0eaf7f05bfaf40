"""The live link module in a browser: job events instead of job polling, reconnect after a
drop, and a revoked token ends the session instead of retrying forever."""

from __future__ import annotations

import httpx
import pytest

from robot.model import ASEA

pytestmark = pytest.mark.e2e

_LIVE_PROBE = """async (token) => {
  const { Live } = await import('/static/js/live.js');
  const live = new Live();
  const seen = [];
  for (const t of ['open', 'close', 'hello', 'job', 'unauthorized'])
    live.addEventListener(t, (ev) => seen.push([t, ev.detail && (ev.detail.reconnected ?? ev.detail.state ?? null)]));
  window.__probe = { live, seen };
  live.start(token);
}"""


def test_jobs_arrive_as_events_and_the_link_reconnects(browser, server):
    token = server.token("e2e-live", "operator")
    page = browser.new_page(viewport={"width": 1400, "height": 900})
    requests: list[str] = []
    page.on("request", lambda r: requests.append(r.url))
    page.goto(server.base + "/")
    page.fill("#token", token)
    page.click("#login")
    page.wait_for_selector("#cell-page")
    page.wait_for_selector("#conn:has-text('live')")

    r = httpx.post(
        f"{server.base}/api/robot/move",
        json={"joints": [float(v) for v in ASEA.q_ready], "speed": 1.0},
        headers={"Authorization": f"Bearer {token}"},
        timeout=10,
    )
    assert r.status_code == 202, r.text
    job_id = r.json()["job"]["id"]
    page.wait_for_selector(f"#jobs li[data-job='{job_id}'].state-done", timeout=30_000)
    # The console learnt of the job and its end from the WebSocket alone.
    assert not [u for u in requests if f"/api/jobs/{job_id}" in u]
    assert sum(1 for u in requests if u.endswith("/api/jobs")) == 1  # the list, once on mount

    page.close()

    # The module on its own, in a page without the 3D view (its software rendering slows
    # everything else): a dropped socket comes back with backoff and says so.
    page = browser.new_page()
    page.goto(server.base + "/")
    page.evaluate(_LIVE_PROBE, token)
    page.wait_for_function("() => window.__probe.seen.some(([t]) => t === 'hello')", polling=250)
    page.evaluate("() => window.__probe.live.ws.close(4000, 'test drop')")
    page.wait_for_function(
        "() => window.__probe.seen.some(([t, r]) => t === 'open' && r === true)",
        timeout=20_000,
        polling=250,
    )
    kinds = [t for t, _ in page.evaluate("() => window.__probe.seen")]
    assert kinds.count("open") == 2 and kinds.count("close") == 1, kinds
    page.evaluate("() => window.__probe.live.stop()")

    # A bad token: one "unauthorized", no retry loop.
    page.evaluate(_LIVE_PROBE, "vc_revoked")
    page.wait_for_function(
        "() => window.__probe.seen.some(([t]) => t === 'unauthorized')", polling=250
    )
    page.wait_for_timeout(2000)
    assert [t for t, _ in page.evaluate("() => window.__probe.seen")] == ["unauthorized"]
    page.close()
