"""A console tab left open across a restart (which revokes the start-up token it signed in
with) returns to the sign-in form at once and sends the dead token no more.

It used to keep polling the camera with it while its WebSocket waited to reconnect: every
request counted as a failed sign-in, the throttle blocked the whole address, the
reconnecting WebSocket got 4429 instead of 4401 (so the tab never signed out), and a valid
token from that address (curl too) got 429 for as long as the tab stayed open.
"""

from __future__ import annotations

import subprocess
import sys
import threading
import time

import httpx
import pytest

from tests.e2e.conftest import Server, start_server

pytestmark = pytest.mark.e2e

READY_S = 300.0  # a start on a loaded machine (a bound, not a timing assertion)


@pytest.fixture
def tab_server(tmp_path):
    s = start_server(tmp_path, ready_s=READY_S)
    yield s
    s.stop()


TIMEOUT = 30.0


def _banner_token(s: Server, start: int = 0) -> str:
    """The start-up token ``visioncell serve`` printed (the last one after line ``start``)."""
    lines = s.log.read_text().splitlines()[start:]
    at = max(
        i for i, line in enumerate(lines) if line.strip().endswith("valid until the next start):")
    )
    return lines[at + 1].strip()


def _start_again(s: Server) -> int:
    """Start the stopped ``s`` again on the same ports and database; returns the log line
    where the new start's output begins."""
    start = len(s.log.read_text().splitlines())
    with s.log.open("a") as log:
        s.proc = subprocess.Popen([sys.executable, "-m", "backend.cli", "serve"], stdout=log,
                                  stderr=subprocess.STDOUT, text=True, env=s.env)  # fmt: skip
    deadline = time.monotonic() + READY_S
    while time.monotonic() < deadline:
        assert s.proc.poll() is None, s.log.read_text()
        try:
            if httpx.get(f"{s.base}/api/health", timeout=1).status_code == 200:
                return start
        except httpx.HTTPError:
            pass
        time.sleep(0.3)
    raise AssertionError(f"the restarted server did not answer within {READY_S:g} s")


def test_a_tab_open_across_a_restart_signs_out_and_stops_its_requests(browser, tab_server):
    server = tab_server
    stale = _banner_token(server)  # what `make run` printed
    sent = {"http": 0, "ws": 0}
    links = [0]  # WebSocket connections the page opened (its live link's attempts)
    lock = threading.Lock()

    def on_request(req):
        if req.headers.get("authorization") == f"Bearer {stale}":
            with lock:
                sent["http"] += 1

    def on_websocket(ws):
        with lock:
            links[0] += 1

        def frame(payload):
            if stale in str(payload):
                with lock:
                    sent["ws"] += 1

        ws.on("framesent", frame)

    page = browser.new_page(viewport={"width": 1280, "height": 800})
    page.on("request", on_request)
    page.on("websocket", on_websocket)
    page.goto(f"{server.base}/#cell")
    page.fill("#token", stale)
    page.click("#login")
    page.wait_for_selector("#cell-page")
    page.wait_for_selector("#conn.on")  # the live link signed in with the token
    page.wait_for_function(  # the camera polls with it
        "() => document.querySelector('#camera').src.startsWith('blob:')", timeout=60_000
    )

    # Down long enough for the live link to back off (0.5, 1, 2, 4, 8 s between attempts),
    # as a cell restarting with its simulator is: then the tab's requests meet the new
    # server well before its link tries again.
    server.stop()
    with lock:
        before = links[0]
    deadline = time.monotonic() + READY_S
    while time.monotonic() < deadline:
        with lock:
            if links[0] >= before + 5:
                break
        page.wait_for_timeout(200)
    start = _start_again(server)
    fresh = {"Authorization": f"Bearer {_banner_token(server, start)}"}
    assert fresh["Authorization"] != f"Bearer {stale}"

    # Back at the sign-in form, with every page stopped.
    page.wait_for_selector("#login-page:not([hidden])", timeout=60_000)
    assert (
        page.is_hidden("#nav")
        and page.eval_on_selector("#page-root", "n => n.children.length") == 0
    )
    assert page.evaluate("() => sessionStorage.getItem('visioncell-token')") is None
    with lock:
        at_sign_out = dict(sent)
    # The camera polled every 0.5 s and the link reconnects within seconds: a few seconds of
    # silence show both stopped (a slow machine only sends fewer requests, never more).
    page.wait_for_timeout(4000)
    with lock:
        assert sent == at_sign_out, (sent, at_sign_out)

    # The address is not blocked: the new token works from it (no 429) ...
    r = httpx.get(f"{server.base}/api/users/me", headers=fresh, timeout=TIMEOUT)
    assert r.status_code == 200, r.text
    # ... and the form says why the tab was signed out.
    assert "no longer accepts this token" in page.text_content("#login-error")

    # A reload does not bring the dead session back.
    page.reload()
    page.wait_for_selector("#login-page:not([hidden])")
    page.wait_for_timeout(1000)
    with lock:
        assert sent == at_sign_out, (sent, at_sign_out)
    page.close()
