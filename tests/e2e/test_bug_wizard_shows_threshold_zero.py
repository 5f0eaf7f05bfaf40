"""The teach wizard after two short teaches: a threshold above 0, what to add, the rounds.

The symptom: after two one-round teaches the console showed the automatic threshold 0.000
("conformal FAR <= 0.01 not reachable ...") and did not say that more rounds or yaws were
needed; a part turned 45 degrees was then named with no pose.  Now, in headless Chromium on
the simulated cell with a token printed by ``visioncell user add``: the wizard guides each
model to the rounds its kind needs (a 3d part: round 2 of 8 after the first, with a progress
bar and the next yaw; a wheel: one round), shows the part's measured height, the threshold
in force (at least the floor) and the advice to teach the 3d part more rounds, and the
Thresholds card says the same.
"""

from __future__ import annotations

import re

import pytest

from backend.recognition.thresholds import MIN_AUTO_THRESHOLD
from tests.e2e.conftest import start_server

pytestmark = pytest.mark.e2e

VIEWPORT = {"width": 1280, "height": 800}


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


def _text(page, sel: str) -> str:
    return page.text_content(sel) or ""


@pytest.mark.timeout(1800)
def test_two_short_teaches_show_a_threshold_above_zero_and_the_rounds_to_add(browser, sim_server):
    token = sim_server.token("wizard-engineer", "engineer")
    page = browser.new_page(viewport=VIEWPORT)
    page.goto(sim_server.base + "/#models")
    page.fill("#token", token)
    page.click("#login")
    page.wait_for_selector("#models-page")
    page.wait_for_selector("#sim-clear:not([hidden])")

    # -- a 3d part, round 1 of 8: backgrounds grabbed, then the object placed ----------------
    page.fill("#new-model-name", "junction-box")
    page.select_option("#new-model-kind", "3d")
    page.click("#new-model")
    page.wait_for_selector('#models-table tr[data-name="junction-box"]')
    page.wait_for_function(
        "() => document.querySelector('#teach-round').textContent.includes('Round 1 of 8')"
    )
    assert "a 3d model needs 8 rounds, 45° apart" in _text(page, "#teach-rounds-why")
    page.click("#sim-clear")
    page.wait_for_function(
        "() => document.querySelector('#teach-message').textContent.includes('station cleared')"
    )
    page.select_option("#teach-background", "grab")
    page.click("#teach-start")
    page.wait_for_selector("#teach-place.attention", timeout=300_000)
    page.select_option("#place-name", "junction-box")
    page.click("#place-object")
    page.wait_for_selector("#teach-result .new-view", timeout=600_000)
    assert "Round 2 of 8" in _text(page, "#teach-round")
    assert "45°" in _text(page, "#teach-round")  # the next yaw: a 360/8 turn
    assert page.eval_on_selector("#teach-rounds-progress", "p => [p.value, p.max]") == [1, 8]
    assert page.input_value("#place-yaw") == "45"  # the simulator turns it next
    height = _text(page, "#teach-height")
    assert re.search(r"Part height \d+\.\d mm \(measured", height), height
    assert "Teach round 2 of 8" in _text(page, "#teach-start")
    # Rounds before the last leave the threshold to the last one, and say what is left.
    assert "deferred to the last round" in _text(page, "#teach-result")
    assert "junction-box (1 of 8)" in _text(page, "#teach-advice")

    # -- a wheel: one round, the stored backgrounds, the object already there ----------------
    page.fill("#new-model-name", "wheel-steel")
    page.select_option("#new-model-kind", "2d")
    page.click("#new-model")
    page.wait_for_function(
        "() => document.querySelector('#model-title').textContent.startsWith('wheel-steel')"
    )
    page.wait_for_function(
        "() => document.querySelector('#teach-round').textContent.includes('Round 1 of 1')"
    )
    assert "a 2d model needs 1 round to be recognised at any yaw" in _text(
        page, "#teach-rounds-why"
    )
    page.click("#sim-clear")
    page.wait_for_function(
        "() => document.querySelector('#teach-message').textContent.includes('station cleared')"
    )
    page.fill("#place-yaw", "0")
    page.select_option("#place-name", "wheel-steel")
    page.click("#place-object")
    page.wait_for_function(
        "() => document.querySelector('#teach-message').textContent.includes('placed')"
    )
    page.select_option("#teach-background", "stored")
    page.click("#teach-start")
    page.wait_for_function(
        "() => document.querySelector('#teach-result').textContent.includes('wheel-steel')",
        timeout=600_000,
    )
    assert _text(page, "#teach-round").startswith("All 1 round taught")
    result = _text(page, "#teach-result")
    m = re.search(r"Threshold in force: (\d\.\d{3})", result)
    assert m is not None, result
    assert float(m.group(1)) >= MIN_AUTO_THRESHOLD > 0.0, result
    advice = _text(page, "#teach-advice")
    assert "Teach more rounds" in advice and "junction-box (1 of 8)" in advice, advice
    assert "wheel-steel (" not in advice, advice
    # The Thresholds card: the same threshold, and the advice.
    page.wait_for_function(
        "() => !document.querySelector('#threshold-advice').hidden", timeout=60_000
    )
    summary = _text(page, "#threshold-summary")
    g = re.search(r"Global threshold (\d\.\d{3})", summary)
    assert g is not None and float(g.group(1)) >= MIN_AUTO_THRESHOLD, summary
    assert "Teach more rounds" in _text(page, "#threshold-advice")
    page.close()
