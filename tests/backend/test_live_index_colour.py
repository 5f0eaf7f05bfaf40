"""The live index keeps a colour signature with every side view (issue 14's twin
tie-break): from the image when a view is uploaded, and from the stored image when the index
is rebuilt at start-up; top views get none of that, but the belt's colour round the object
(the light they were taught under)."""

from __future__ import annotations

import time

import numpy as np
from fastapi.testclient import TestClient

from backend.app import create_app
from tests.utils.factories import make_settings, make_tokens, migrate
from tests.utils.models import png_bytes, textured_rgb


def _upload(client, hdr, model_id, seed, viewpoint):
    files = [("images", (f"v{seed}.png", png_bytes(textured_rgb(seed)), "image/png"))]
    r = client.post(
        f"/api/models/{model_id}/views",
        files=files,
        data={"viewpoints": str(viewpoint)},
        headers=hdr,
    )
    assert r.status_code == 201, r.text
    return r.json()["data"][0]["id"]


def _colours(client):
    with client.app.state.runtime.live_index.reading() as index:
        return {v.view_id: (v.colour, v.outline) for v in index.views}


def test_side_views_have_colour_after_upload_and_restart(tmp_path):
    settings = make_settings(tmp_path)
    migrate(settings)
    hdr = {"Authorization": f"Bearer {make_tokens(settings)['engineer']}"}
    with TestClient(create_app(settings)) as client:
        r = client.post("/api/models", json={"name": "wheel", "kind": "3d", "part": "wheel"},
                        headers=hdr)  # fmt: skip
        assert r.status_code == 201, r.text
        mid = r.json()["id"]
        top = _upload(client, hdr, mid, 1, 1)
        side = _upload(client, hdr, mid, 2, 2)
        live = _colours(client)
    assert live[top] == (None, None)
    colour, outline = live[side]
    assert colour is not None and outline is not None and colour.sum() > 0.99
    with TestClient(create_app(settings)) as client:  # rebuilt from the database
        again = _colours(client)
    assert again[top] == (None, None)
    assert again[side][0] is not None
    assert abs(again[side][0] - colour).max() < 1e-6


def test_a_side_view_taught_by_another_cell_arrives_with_its_colour(tmp_path):
    url = f"sqlite+aiosqlite:///{tmp_path / 'plant.db'}"
    a = make_settings(tmp_path / "a", database_url=url, cell_name="cell-a", index_poll_s=0.1)
    b = make_settings(tmp_path / "b", database_url=url, cell_name="cell-b", index_poll_s=0.1)
    migrate(a)
    hdr = {"Authorization": f"Bearer {make_tokens(a)['engineer']}"}
    with TestClient(create_app(a)) as ca, TestClient(create_app(b)) as cb:
        r = ca.post("/api/models", json={"name": "wheel", "kind": "3d", "part": "wheel"},
                    headers=hdr)  # fmt: skip
        assert r.status_code == 201, r.text
        side = _upload(ca, hdr, r.json()["id"], 2, 3)
        t0 = time.monotonic()
        while side not in _colours(cb) and time.monotonic() - t0 < 20.0:
            time.sleep(0.05)
        colour, outline = _colours(cb)[side]
        expected = _colours(ca)[side][0]
        # A top view taught there brings the belt's colour of its light here too.
        _upload_masked(ca, hdr, r.json()["id"], *_belt_view(4, (90, 100, 110)))
        t0 = time.monotonic()
        while cb.app.state.runtime.live_index.light_reference() is None:
            assert time.monotonic() - t0 < 20.0, "the top view's belt colour never arrived"
            time.sleep(0.05)
        np.testing.assert_allclose(
            cb.app.state.runtime.live_index.light_reference(), (90, 100, 110)
        )
    assert colour is not None and outline is not None and expected is not None
    assert abs(colour - expected).max() < 1e-6


def _belt_view(seed: int, belt: tuple[int, int, int]):
    """A textured part inside a mask on a plain belt of colour ``belt``: image and mask."""
    img = textured_rgb(seed)
    mask = np.zeros(img.shape[:2], np.uint8)
    mask[60:180, 80:240] = 255
    out = np.empty_like(img)
    out[:] = belt
    out[mask > 0] = img[mask > 0]
    return out, mask


def _upload_masked(client, hdr, model_id, image, mask):
    files = [
        ("images", ("top.png", png_bytes(image), "image/png")),
        ("masks", ("top-mask.png", png_bytes(mask), "image/png")),
    ]
    r = client.post(f"/api/models/{model_id}/views", files=files, data={"viewpoints": "1"},
                    headers=hdr)  # fmt: skip
    assert r.status_code == 201, r.text
    return r.json()["data"][0]["id"]


def test_top_views_give_the_teach_lights_belt_colour(tmp_path):
    """The belt's colour round each top view, the light reference of the inspections'
    light balance: from an upload with its mask, again from the database after a restart,
    the median over views, gone with the view."""
    settings = make_settings(tmp_path)
    migrate(settings)
    hdr = {"Authorization": f"Bearer {make_tokens(settings)['engineer']}"}
    with TestClient(create_app(settings)) as client:
        live = client.app.state.runtime.live_index
        assert live.light_reference() is None
        r = client.post("/api/models", json={"name": "gear", "kind": "3d"}, headers=hdr)
        mid = r.json()["id"]
        _upload(client, hdr, mid, 3, 1)  # no mask: no belt to tell the light by
        assert live.light_reference() is None
        ids = [
            _upload_masked(client, hdr, mid, *_belt_view(s, belt))
            for s, belt in ((4, (90, 100, 110)), (5, (92, 100, 112)), (6, (200, 40, 40)))
        ]
        np.testing.assert_allclose(live.light_reference(), (92, 100, 110))  # median
    with TestClient(create_app(settings)) as client:  # rebuilt from the database
        live = client.app.state.runtime.live_index
        np.testing.assert_allclose(live.light_reference(), (92, 100, 110))
        for vid in ids[1:]:
            r = client.delete(f"/api/models/{mid}/views/{vid}", headers=hdr)
            assert r.status_code == 204, r.text
        np.testing.assert_allclose(live.light_reference(), (90, 100, 110))
        assert client.delete(f"/api/models/{mid}", headers=hdr).status_code == 204
        assert live.light_reference() is None
