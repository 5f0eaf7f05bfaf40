"""The whole product in a browser: sign in, press Home, see the arm in the 3D view."""

from __future__ import annotations

import io
import math

import httpx
import numpy as np
import pytest
from PIL import Image

from robot.model import ASEA

pytestmark = pytest.mark.e2e

#: Bounds each wait on the page (a hang), never a claim about speed: on a loaded machine
#: Chromium's software rendering and viser's page take long to arrive.
HANG_MS = 180_000


def _screenshot_array(page) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(page.screenshot())).convert("RGB"), dtype=np.float64)


def _drawn(img: np.ndarray) -> bool:
    """Enough distinct colours and spread to be a drawn scene, not a flat page."""
    return img.std() > 10.0 and len(np.unique((img[::4, ::4] // 16).reshape(-1, 3), axis=0)) > 20


def _joint_texts(page) -> list[float]:
    return [float(page.inner_text(f'[data-joint="{i}"]')) for i in range(5)]


def test_console_login_home_and_3d_view(browser, server):
    token = server.token("e2e-operator", "operator")
    # Put the arm somewhere other than home first, through the REST API.
    ready = [float(v) for v in ASEA.q_ready]
    r = httpx.post(
        f"{server.base}/api/robot/move?wait=true",
        json={"joints": ready, "speed": 1.0},
        headers={"Authorization": f"Bearer {token}"},
        timeout=30,
    )
    assert r.status_code == 200, r.text

    page = browser.new_page(viewport={"width": 1400, "height": 900})
    page.goto(server.base + "/")
    page.fill("#token", "vc_wrong")
    page.click("#login")
    page.wait_for_selector("#login-error:has-text('not valid')", timeout=HANG_MS)
    page.fill("#token", token)
    page.click("#login")
    page.wait_for_selector("#cell-page:not([hidden])", timeout=HANG_MS)
    page.wait_for_selector("#conn:has-text('live')", timeout=HANG_MS)
    before = _joint_texts(page)
    assert before == pytest.approx([round(math.degrees(v), 2) for v in ready], abs=0.011)
    assert page.get_attribute("a[href='/docs']", "href") == "/docs"

    page.click("#home")
    home = [round(math.degrees(v), 2) for v in ASEA.q_home]
    page.wait_for_function(
        'home => [0,1,2,3,4].every(i => Math.abs(parseFloat(document.querySelector(`[data-joint="${i}"]`).textContent) - home[i]) < 0.02)',
        arg=home,
        timeout=HANG_MS,
    )
    after = _joint_texts(page)
    assert after != before and after == pytest.approx(home, abs=0.011)
    # Waits until the embedded view has drawn its canvas (is_visible() would not wait).
    page.frame_locator("#view3d").locator("canvas").first.wait_for(state="visible", timeout=HANG_MS)
    page.wait_for_function(
        "() => document.querySelector('#camera').src.startsWith('blob:')", timeout=HANG_MS
    )
    page.close()

    # The viser page on its own: the scene must not be blank.
    view = browser.new_page(viewport={"width": 1000, "height": 700})
    view.goto(server.viser + "/")
    view.wait_for_selector("canvas", timeout=HANG_MS)
    # The scene is drawn once the page has loaded it: look until it is (bounded).
    for _ in range(HANG_MS // 2000):
        img = _screenshot_array(view)
        if _drawn(img):
            break
        view.wait_for_timeout(2000)
    view.close()
    assert _drawn(img), (img.std(), len(np.unique((img[::4, ::4] // 16).reshape(-1, 3), axis=0)))

    # Ctrl-C stops everything: the process exits by itself (stop() kills it after 120 s,
    # which leaves -9). A bound on behaviour, not a timing target (5 s seen under load).
    took = server.stop(timeout=120.0)
    assert server.proc.returncode == 0, f"no clean exit {took:.1f} s after Ctrl-C"
    assert server.proc.returncode == 0
