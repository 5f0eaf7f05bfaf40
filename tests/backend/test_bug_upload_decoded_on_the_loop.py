"""Uploads were decoded (and their features extracted) on the event loop: twenty 12-MP PNGs
blocked ``/api/health`` for 28 s, a few pushed RSS past 3 GB, and the work went on after the
client had left.

The decode is replaced by one that blocks on an event: had it run on the loop, the health
probe and E-STOP sent meanwhile would hang (each is bounded by a generous timeout).
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import threading

import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from backend.recognition import images as im
from tests.utils.asgi import exchange
from tests.utils.factories import make_settings, make_tokens, migrate
from tests.utils.models import jpeg_bytes, png_bomb, png_bytes, textured_rgb

HANG_S = 60.0


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("uploads")
    settings = make_settings(tmp, max_request_pixels=1_000_000)
    migrate(settings)
    tokens = make_tokens(settings)
    app = create_app(settings)
    with TestClient(app) as client:
        yield app, client, {r: {"Authorization": f"Bearer {t}"} for r, t in tokens.items()}


@pytest.fixture
def model_id(served) -> int:
    _, client, h = served
    n = len(client.get("/api/models", headers=h["viewer"]).json()["data"])
    r = client.post("/api/models", json={"name": f"part-{n}", "kind": "2d"}, headers=h["engineer"])
    assert r.status_code == 201, r.text
    return r.json()["id"]


class HeldDecode:
    """``im.decode_image`` that blocks on its first call until released, counting calls."""

    def __init__(self) -> None:
        self.real = im.decode_image
        self.started = threading.Event()
        self.release = threading.Event()
        self.calls = 0

    def __call__(self, *args, **kwargs):
        self.calls += 1
        if self.calls == 1:
            self.started.set()
            assert self.release.wait(HANG_S), "the held decode was never released"
        return self.real(*args, **kwargs)


def views_files(*images: bytes) -> list:
    return [("images", (f"v{k}.png", data, "image/png")) for k, data in enumerate(images)]


def view_count(client, h, model_id: int) -> int:
    r = client.get(f"/api/models/{model_id}/views", headers=h["viewer"])
    assert r.status_code == 200, r.text
    return r.json()["count"]


def test_health_and_estop_answer_while_an_upload_is_decoded(served, model_id, monkeypatch):
    _, client, h = served
    held = HeldDecode()
    monkeypatch.setattr(im, "decode_image", held)
    with concurrent.futures.ThreadPoolExecutor(2) as pool:
        upload = pool.submit(
            client.post, f"/api/models/{model_id}/views",
            files=views_files(png_bytes(textured_rgb(1))), headers=h["engineer"],
        )  # fmt: skip
        try:
            assert held.started.wait(HANG_S), "the upload never reached its decode"
            # the decode is held in a pool thread: the loop still answers
            health = pool.submit(client.get, "/api/health").result(timeout=HANG_S)
            assert health.status_code == 200
            estop = client.post("/api/robot/estop", headers=h["viewer"])
            assert estop.status_code == 200, estop.text
            assert not upload.done()
        finally:
            held.release.set()
        r = upload.result(timeout=HANG_S)
    assert r.status_code == 201, r.text
    assert client.post("/api/robot/reset", headers=h["operator"]).status_code == 200


def test_an_image_bomb_is_refused_from_its_header(served, model_id, monkeypatch):
    _, client, h = served
    held = HeldDecode()
    held.release.set()
    monkeypatch.setattr(im, "decode_image", held)
    r = client.post(f"/api/models/{model_id}/views", files=views_files(png_bomb(50_000, 50_000)),
                    headers=h["engineer"])  # fmt: skip
    assert r.status_code == 413, r.text
    assert r.json()["error"] == "too_large" and "50000 x 50000" in r.json()["detail"]
    assert held.calls == 0


def test_a_12_megapixel_png_of_a_few_kb_is_refused_before_it_is_decoded(
    served, model_id, monkeypatch
):
    app, client, h = served
    held = HeldDecode()
    held.release.set()
    monkeypatch.setattr(im, "decode_image", held)
    monkeypatch.setattr(app.state.runtime.heavy, "max_pixels", 64_000_000)  # the default
    bomb = png_bomb(4000, 3000)  # within the 12-MP limit per image; SIFT would take GBs
    assert len(bomb) < 50_000
    r = client.post(f"/api/models/{model_id}/views", files=views_files(bomb),
                    headers=h["engineer"])  # fmt: skip
    assert r.status_code == 413, r.text
    assert "4000 x 3000" in r.json()["detail"] and "at most 4194304 px" in r.json()["detail"]
    assert held.calls == 0


def test_a_request_over_its_pixel_budget_is_refused_before_the_decode_that_passes_it(
    served, model_id, monkeypatch
):
    _, client, h = served
    held = HeldDecode()
    held.release.set()
    monkeypatch.setattr(im, "decode_image", held)
    # 1 MP per request here: the first 800 x 700 image fits, the second would pass it
    img = png_bytes(textured_rgb(2, size=(700, 800)))
    r = client.post(f"/api/models/{model_id}/views", files=views_files(img, img),
                    headers=h["engineer"])  # fmt: skip
    assert r.status_code == 413, r.text
    assert r.json()["error"] == "too_large"
    assert "at most 1000000 pixels" in r.json()["detail"]
    assert held.calls == 1  # the second image was never decoded
    assert view_count(client, h, model_id) == 0


def test_a_truncated_image_is_a_4xx(served, model_id):
    _, client, h = served
    jpeg = jpeg_bytes(textured_rgb(3))
    r = client.post(f"/api/models/{model_id}/views",
                    files=[("images", ("cut.jpg", jpeg[: len(jpeg) // 2], "image/jpeg"))],
                    headers=h["engineer"])  # fmt: skip
    assert r.status_code == 415, r.text
    assert r.json()["error"] == "unsupported_media_type"
    png = png_bytes(textured_rgb(4))
    r = client.post("/api/calibration/sessions", headers=h["engineer"], json={
        "kind": "intrinsic", "board": {"type": "chessboard", "cols": 9, "rows": 6, "square_mm": 30}})  # fmt: skip
    assert r.status_code == 201, r.text
    sid = r.json()["session"]["id"]
    r = client.post(f"/api/calibration/sessions/{sid}/samples",
                    files=[("images", ("cut.png", png[: len(png) // 2], "image/png"))],
                    headers=h["engineer"])  # fmt: skip
    assert r.status_code == 415, r.text
    assert view_count(client, h, model_id) == 0


def test_a_client_that_disconnects_cancels_its_queued_work(served, model_id, monkeypatch):
    app, client, h = served
    held = HeldDecode()
    monkeypatch.setattr(im, "decode_image", held)
    extracted = []
    from backend.recognition import views as views_svc

    real_prepare = views_svc._prepare_one
    monkeypatch.setattr(
        views_svc, "_prepare_one", lambda *a: extracted.append(1) or real_prepare(*a)
    )
    img = png_bytes(textured_rgb(5, size=(240, 320)))
    boundary = "edge-test-boundary"
    body = (
        b"".join(
            f'--{boundary}\r\nContent-Disposition: form-data; name="images"; filename="v{k}.png"\r\n'
            f"Content-Type: image/png\r\n\r\n".encode()
            + img
            + b"\r\n"
            for k in range(2)
        )
        + f"--{boundary}--\r\n".encode()
    )
    headers = {"authorization": h["engineer"]["Authorization"],
               "content-type": f"multipart/form-data; boundary={boundary}",
               "content-length": str(len(body))}  # fmt: skip

    async def scenario():
        gone = asyncio.Event()
        request = asyncio.create_task(
            exchange(
                app,
                "POST",
                f"/api/models/{model_id}/views",
                headers=headers,
                chunks=[body],
                disconnect=gone,
            )
        )
        assert await asyncio.to_thread(held.started.wait, HANG_S)
        gone.set()  # the client leaves while its first image is decoded
        ex = await asyncio.wait_for(request, HANG_S)
        held.release.set()
        rt = app.state.runtime
        async with asyncio.timeout(HANG_S):
            while rt.heavy.free_slots != rt.heavy.max_jobs:  # the running unit ends
                await asyncio.sleep(0.01)
        return ex

    try:
        ex = client.portal.call(scenario)
    finally:
        held.release.set()
    assert ex.status == 499 and ex.json()["error"] == "client_closed_request"
    assert held.calls == 1 and extracted == []  # nothing after the client left
    assert view_count(client, h, model_id) == 0


def test_the_threshold_choice_runs_in_the_pool(served, monkeypatch):
    from backend.recognition import thresholds

    app, client, h = served
    for seed in (21, 31):
        mid = client.post("/api/models", json={"name": f"thr-{seed}", "kind": "2d"},
                          headers=h["engineer"]).json()["id"]  # fmt: skip
        files = views_files(*(png_bytes(textured_rgb(seed + k)) for k in range(3)))
        r = client.post(f"/api/models/{mid}/views", files=files, headers=h["engineer"])
        assert r.status_code == 201, r.text
    rt = app.state.runtime
    ran = []
    real = rt.heavy._submit
    monkeypatch.setattr(
        rt.heavy, "_submit", lambda fn, *a, **kw: ran.append(fn) or real(fn, *a, **kw)
    )
    outcome = client.portal.call(
        lambda: thresholds.recompute(rt.database, rt.live_index, heavy=rt.heavy)
    )
    assert outcome.threshold is not None, outcome.reason
    assert thresholds._choose in ran
