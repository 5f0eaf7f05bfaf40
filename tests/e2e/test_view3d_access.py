"""The 3D view in a real browser: an anonymous viser page has no controls and moves nothing;
the console's embedded view arrives signed in and its Home button moves the arm; a token
typed into a bare viser page signs it in; revoking the token takes the controls away."""

from __future__ import annotations

import math
import time

import httpx
import pytest

from robot.model import ASEA

pytestmark = pytest.mark.e2e

#: Bounds each wait on the page (a hang), never a claim about speed.
HANG_MS = 180_000


def _joints(server, token: str) -> list[float]:
    r = httpx.get(
        f"{server.base}/api/robot/state", headers={"Authorization": f"Bearer {token}"}, timeout=10
    )
    return r.json()["state"]["q"]


def _move_ready(server, token: str) -> list[float]:
    ready = [float(v) for v in ASEA.q_ready]
    r = httpx.post(
        f"{server.base}/api/robot/move?wait=true",
        json={"joints": ready, "speed": 1.0},
        headers={"Authorization": f"Bearer {token}"},
        timeout=30,
    )
    assert r.status_code == 200, r.text
    return ready


def _close_to(q: list[float], target: list[float]) -> bool:
    return all(abs(a - b) < 1e-4 for a, b in zip(q, target, strict=True))


def test_anonymous_viser_page_shows_no_controls_and_a_token_signs_it_in(browser, shared_server):
    server = shared_server
    op = server.token("e2e-view-op", "operator")
    eng = server.token("e2e-view-eng", "engineer")
    ready = _move_ready(server, op)

    view = browser.new_page(viewport={"width": 1100, "height": 800})
    view.goto(server.viser + "/")
    view.get_by_text("Not signed in").wait_for(timeout=60_000)
    for label in ("Home", "Reset E-STOP", "Stop", "E-STOP", "Speed"):
        assert view.get_by_role("button", name=label, exact=True).count() == 0, label
    assert view.get_by_text("Speed", exact=True).count() == 0
    time.sleep(1.0)
    assert _close_to(_joints(server, op), ready)

    # A wrong token is refused; the operator's token gives the operator's controls.
    # viser's label does not point at its input (its `for` is the element's uuid).
    field = view.locator("xpath=//label[normalize-space()='API token']/following::input[1]")
    field.fill("vc_wrong")
    view.get_by_role("button", name="Sign in").click()
    view.get_by_text("That token is not valid").wait_for(timeout=30_000)
    field.fill(op)
    view.get_by_role("button", name="Sign in").click()
    view.get_by_text("Signed in as").wait_for(timeout=30_000)
    assert field.count() == 0 or field.input_value() == ""  # the token is not left on screen
    home = view.get_by_role("button", name="Home", exact=True)
    home.click(timeout=30_000)
    deadline = time.monotonic() + 30
    while not _close_to(_joints(server, op), [float(v) for v in ASEA.q_home]):
        assert time.monotonic() < deadline, "the signed-in operator's Home did not move the arm"
        time.sleep(0.2)

    # Revoking the operator's tokens (an engineer disables the user) removes the controls.
    r = httpx.delete(
        f"{server.base}/api/users/e2e-view-op",
        headers={"Authorization": f"Bearer {eng}"},
        timeout=10,
    )
    assert r.status_code == 200, r.text
    view.get_by_text("Not signed in").wait_for(timeout=30_000)
    assert view.get_by_role("button", name="Home", exact=True).count() == 0
    view.close()


def test_the_console_view_arrives_signed_in_and_moves_the_arm(browser, shared_server):
    server = shared_server
    op = server.token("e2e-embed-op", "operator")
    ready = _move_ready(server, op)
    page = browser.new_page(viewport={"width": 1400, "height": 900})
    page.goto(server.base + "/")
    page.fill("#token", op)
    page.click("#login")
    page.wait_for_selector("#cell-page", timeout=HANG_MS)
    src = page.wait_for_function(
        "() => document.querySelector('#view3d').src.includes('vc-link')",
        timeout=HANG_MS,
        polling=250,
    )
    assert src
    frame = page.frame_locator("#view3d")
    frame.get_by_text("Signed in as").wait_for(timeout=HANG_MS)
    assert "console link" in frame.get_by_text("Signed in as").inner_text()
    frame.get_by_role("button", name="Home", exact=True).click(timeout=HANG_MS)
    home = [round(math.degrees(v), 2) for v in ASEA.q_home]
    page.wait_for_function(
        'home => [0,1,2,3,4].every(i => Math.abs(parseFloat(document.querySelector(`[data-joint="${i}"]`).textContent) - home[i]) < 0.02)',
        arg=home,
        polling=250,
        timeout=HANG_MS,
    )
    assert not _close_to(_joints(server, op), ready)

    # Signing out of the console unmounts the page: the embedded view's connection closes.
    page.click("#logout")
    page.wait_for_selector("#login-page:not([hidden])", timeout=HANG_MS)
    deadline = time.monotonic() + HANG_MS / 1000
    while True:
        status = httpx.get(
            f"{server.base}/api/status", headers={"Authorization": f"Bearer {op}"}, timeout=10
        ).json()["view3d"]
        if status["clients"] == 0:
            break
        assert time.monotonic() < deadline, status
        time.sleep(0.3)
    page.close()
