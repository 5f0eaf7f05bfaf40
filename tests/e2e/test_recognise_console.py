"""The Recognise page: an operator picks an image and sees the decision, every model's score
against its threshold and the matched outline drawn on the canvas, stores it as an
inspection, without a CSP violation; the automatic threshold's state and rule are shown."""

from __future__ import annotations

import cv2
import httpx
import numpy as np
import pytest

from tests.utils.models import png_bytes, textured_rgb

pytestmark = pytest.mark.e2e

_LISTEN = """
window.__csp = [];
document.addEventListener('securitypolicyviolation',
  e => window.__csp.push(e.violatedDirective + ' ' + e.blockedURI));
"""


def _grey(seed: int) -> np.ndarray:
    g = cv2.cvtColor(textured_rgb(seed), cv2.COLOR_RGB2GRAY)
    return np.dstack([g] * 3)


def test_recognise_page_shows_decision_scores_and_outline(browser, server, tmp_path):
    eng = server.token("e2e-rec-eng", "engineer")
    op = server.token("e2e-rec-op", "operator")
    img = _grey(41)  # grey: the only green on the canvas is the drawn outline
    with httpx.Client(base_url=server.base + "/api", timeout=120,
                      headers={"Authorization": f"Bearer {eng}"}) as c:  # fmt: skip
        for name, seed in (("gear-b", 41), ("plate", 42)):
            m = c.post("/models", json={"name": name, "kind": "2d"}).json()
            r = c.post(f"/models/{m['id']}/views", files=[
                ("images", ("v.png", png_bytes(_grey(seed)), "image/png")),
                ("images", ("w.png", png_bytes(_grey(seed)[:, ::-1].copy()), "image/png")),
            ])  # fmt: skip
            assert r.status_code == 201, r.text
    query = tmp_path / "query.png"
    query.write_bytes(png_bytes(img))

    context = browser.new_context(viewport={"width": 1280, "height": 900})
    context.add_init_script(_LISTEN)
    page = context.new_page()
    console: list[str] = []
    page.on("console", lambda m: console.append(m.text))
    try:
        page.goto(server.base + "/#recognise")
        page.fill("#token", op)
        page.click("#login")
        page.wait_for_selector("#recognise-page")
        page.set_input_files("#recognise-file", str(query))
        page.check("#recognise-store")
        page.click("#recognise-run")
        page.wait_for_selector("#recognise-decision[data-decision]", timeout=60_000)
        assert page.get_attribute("#recognise-decision", "data-decision") == "recognized"
        assert "recognized: gear-b" in page.inner_text("#recognise-decision")
        rows = page.eval_on_selector_all(
            "#recognise-scores tbody tr", "rs => rs.map(r => r.dataset.model)"
        )
        assert rows == ["gear-b", "plate"]
        assert "stored as inspection" in page.inner_text("#recognise-pose")
        page.wait_for_function(
            "() => Number(document.querySelector('#recognise-canvas').dataset.outline) >= 3"
        )
        # The outline is drawn: the canvas holds green pixels the image has none of.
        green = page.evaluate("""() => {
          const c = document.querySelector('#recognise-canvas');
          const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
          let n = 0;
          for (let i = 0; i < d.length; i += 4) if (d[i + 1] > 150 && d[i] < 60 && d[i + 2] < 90) n++;
          return n;
        }""")
        assert green > 50
        state = page.inner_text("#threshold-state")
        assert "Follows every change" in state
        assert "Global threshold" in page.inner_text("#threshold-rule")
        seen = [m for m in console if "Content Security Policy" in m or "Refused to" in m]
        assert seen + list(page.evaluate("window.__csp")) == []
    finally:
        context.close()
