"""The module console in a browser: the hash router with Back/Forward, pages that stop their
streams on unmount, the camera polled only while visible, and no request off localhost."""

from __future__ import annotations

from urllib.parse import urlsplit

import pytest

pytestmark = pytest.mark.e2e

LOCAL = {"127.0.0.1", "localhost"}


def _sign_in(page, server, token: str, path: str = "/") -> None:
    page.goto(server.base + path)
    page.fill("#token", token)
    page.click("#login")
    page.wait_for_selector("#nav:not([hidden])")


def _frames_requested(requests: list[str]) -> int:
    return sum(1 for u in requests if u.endswith("/api/camera/frame.jpg"))


def test_back_and_forward_move_between_pages_and_unmount_stops_polling(browser, shared_server):
    server = shared_server
    token = server.token("e2e-router", "operator")
    page = browser.new_page(viewport={"width": 1400, "height": 900})
    requests: list[str] = []
    page.on("request", lambda r: requests.append(r.url))
    _sign_in(page, server, token)
    page.wait_for_selector("#cell-page")
    assert page.url.endswith("#cell")
    page.wait_for_function(
        "() => document.querySelector('#camera').src.startsWith('blob:')", polling=250
    )
    assert page.eval_on_selector_all("#nav-pages a", "as => as.map(a => a.textContent)") == [
        "Cell",
        "Inspection",
        "Models",
        "Recipes",
        "Recognise",
        "Reports",
        "Calibration",
    ]

    page.click("a[data-page='calibration']")
    page.wait_for_selector("#calibration-page")
    assert page.query_selector("#cell-page") is None  # unmounted, not just hidden
    assert page.url.endswith("#calibration")
    assert "active" in page.get_attribute("a[data-page='calibration']", "class")
    # The Cell page's camera timer stopped with it.
    page.wait_for_timeout(300)
    n = _frames_requested(requests)
    page.wait_for_timeout(2000)
    assert _frames_requested(requests) == n

    page.go_back()
    page.wait_for_selector("#cell-page")
    assert page.query_selector("#calibration-page") is None
    assert page.url.endswith("#cell")
    page.go_forward()
    page.wait_for_selector("#calibration-page")
    assert page.query_selector("#cell-page") is None
    page.go_back()
    page.wait_for_selector("#cell-page")

    # An unknown page falls back to the first one; the live link stayed up throughout.
    page.evaluate("() => { location.hash = '#nowhere'; }")
    page.wait_for_function("() => location.hash === '#cell'", polling=250)
    assert page.inner_text("#conn") == "live"

    # Each page module has the registry's shape.
    shapes = page.evaluate(
        """async () => Promise.all(['cell', 'calibration'].map(async (n) => {
             const m = (await import(`/static/js/pages/${n}.js`)).default;
             return [m.id, typeof m.title, m.minRole, typeof m.mount, typeof m.unmount];
           }))"""
    )
    assert shapes == [
        ["cell", "string", "viewer", "function", "function"],
        ["calibration", "string", "viewer", "function", "function"],
    ]

    # Sign-out unmounts the page and closes the link.
    page.click("#logout")
    page.wait_for_selector("#login-page:not([hidden])")
    assert page.query_selector("#cell-page") is None
    page.wait_for_selector("#conn:has-text('offline')")
    page.close()


def test_the_camera_is_polled_only_while_the_image_is_visible(browser, shared_server):
    server = shared_server
    token = server.token("e2e-camera", "viewer")
    # One column under 1100 px: the camera card sits below the fold of a short window.
    page = browser.new_page(viewport={"width": 900, "height": 500})
    requests: list[str] = []
    page.on("request", lambda r: requests.append(r.url))
    _sign_in(page, server, token)
    page.wait_for_selector("#cell-page")
    page.wait_for_selector("#conn:has-text('live')")
    page.wait_for_timeout(1500)
    assert _frames_requested(requests) == 0
    assert page.is_hidden("#home")  # viewers get E-STOP only
    assert page.is_visible("#estop")

    page.eval_on_selector("#camera", "img => img.scrollIntoView()")
    page.wait_for_function(
        "() => document.querySelector('#camera').src.startsWith('blob:')",
        timeout=15_000,
        polling=250,
    )
    for _ in range(100):  # polling, while on screen (slowly: the 3D view renders in software)
        if _frames_requested(requests) >= 3:
            break
        page.wait_for_timeout(200)
    assert _frames_requested(requests) >= 3

    page.evaluate("() => window.scrollTo(0, 0)")
    page.wait_for_timeout(500)
    n = _frames_requested(requests)
    page.wait_for_timeout(3000)
    assert _frames_requested(requests) <= n + 1  # at most the one already in flight
    page.close()


def test_the_console_makes_no_request_off_localhost(browser, shared_server):
    server = shared_server
    token = server.token("e2e-offline", "engineer")
    page = browser.new_page(viewport={"width": 1400, "height": 900})
    urls: list[str] = []
    page.on("request", lambda r: urls.append(r.url))
    page.on("websocket", lambda ws: urls.append(ws.url))
    _sign_in(page, server, token)
    page.wait_for_selector("#cell-page")
    page.wait_for_selector("#conn:has-text('live')")
    page.frame_locator("#view3d").locator("canvas").first.wait_for(timeout=60_000)
    page.wait_for_timeout(2000)
    page.click("a[data-page='calibration']")
    page.wait_for_selector("#calibration-page")
    page.wait_for_timeout(500)
    page.go_back()
    page.wait_for_selector("#cell-page")
    page.wait_for_timeout(1500)
    page.close()

    hosts = {urlsplit(u).hostname for u in urls if not u.startswith(("blob:", "data:", "about:"))}
    assert hosts and hosts <= LOCAL, sorted(u for u in urls if urlsplit(u).hostname not in LOCAL)
    # The embedded view came from the viser port and opened its websocket there.
    viser_port = urlsplit(server.viser).port
    assert any(urlsplit(u).port == viser_port and u.startswith("ws") for u in urls)
