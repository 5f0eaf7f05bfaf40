"""A console tab whose token is revoked (as a restart revokes the start-up token) returns to
the sign-in form at once and sends the token no more.

It used to keep polling the camera and reconnecting its WebSocket with the dead token:
every request counted as a failed sign-in, so within seconds the sign-in throttle blocked
the whole address and a valid engineer token from it (curl too) got 429 for as long as the
tab stayed open.
"""

from __future__ import annotations

import threading

import httpx
import pytest

pytestmark = pytest.mark.e2e

TIMEOUT = 30.0


def test_a_revoked_token_signs_the_tab_out_and_stops_its_requests(browser, server):
    engineer = {"Authorization": f"Bearer {server.token('stale-engineer', 'engineer')}"}
    stale = server.token("stale-tab", "operator")
    sent = {"http": 0, "ws": 0}
    lock = threading.Lock()

    def on_request(req):
        if req.headers.get("authorization") == f"Bearer {stale}":
            with lock:
                sent["http"] += 1

    def on_websocket(ws):
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

    tokens = httpx.get(f"{server.base}/api/users/stale-tab/tokens", headers=engineer,
                       timeout=TIMEOUT).json()["data"]  # fmt: skip
    for t in tokens:
        r = httpx.delete(f"{server.base}/api/users/stale-tab/tokens/{t['id']}", headers=engineer,
                         timeout=TIMEOUT)  # fmt: skip
        assert r.status_code == 200, r.text

    # Back at the sign-in form, saying why, with every page stopped.
    page.wait_for_selector("#login-page:not([hidden])", timeout=60_000)
    assert (
        page.is_hidden("#nav")
        and page.eval_on_selector("#page-root", "n => n.children.length") == 0
    )
    assert page.evaluate("() => sessionStorage.getItem('visioncell-token')") is None
    with lock:
        at_sign_out = dict(sent)
    # The camera polled every 0.5 s and the link reconnected within seconds: a few seconds of
    # silence show both stopped (a slow machine only sends fewer requests, never more).
    page.wait_for_timeout(4000)
    with lock:
        assert sent == at_sign_out, (sent, at_sign_out)

    # The address is not blocked: a valid token from it still works (no 429).
    r = httpx.get(f"{server.base}/api/users/me", headers=engineer, timeout=TIMEOUT)
    assert r.status_code == 200, r.text
    assert r.json()["name"] == "stale-engineer"
    assert "no longer accepts this token" in page.text_content("#login-error")

    # A reload does not bring the dead session back either.
    before = dict(sent)
    page.reload()
    page.wait_for_selector("#login-page:not([hidden])")
    page.wait_for_timeout(1000)
    assert sent == before  # nothing sent with the stale token
    page.close()
