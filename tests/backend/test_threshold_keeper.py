"""The automatic threshold follows every change of the trained views: one coalesced
``threshold`` job per run of changes, skipped when nothing it depends on changed, and a
single model gets a threshold from negative images (never 0, with advice in words)."""

from __future__ import annotations

import asyncio
import time

import cv2
import numpy as np
import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from backend.db.session import Database
from backend.jobs import JobManager
from backend.recognition.autothreshold import ThresholdKeeper
from backend.recognition.index import IndexedModel, LiveIndex
from backend.recognition.thresholds import latest_settings
from tests.utils.factories import make_settings, make_tokens, migrate
from tests.utils.models import png_bytes, textured_rgb
from vision.recognition import THRESHOLD_FLOOR

#: Bounds a hang only; the work takes seconds.
TIMEOUT_S = 300.0


def _turned(rgb: np.ndarray, angle_deg: float) -> np.ndarray:
    h, w = rgb.shape[:2]
    M = cv2.getRotationMatrix2D((w / 2, h / 2), angle_deg, 1.0)
    return cv2.warpAffine(rgb, M, (w, h), borderValue=(128, 128, 128))


def test_many_changes_in_a_row_give_one_recomputation(tmp_path):
    settings = make_settings(tmp_path)
    migrate(settings)

    async def run() -> None:
        db = Database(settings.database_url)
        live = LiveIndex()
        jobs = JobManager()
        belt = np.full((240, 320, 3), 90, np.uint8)  # a teach's empty-belt background
        keeper = ThresholdKeeper(db, live, jobs, quiet_s=0.0, backgrounds=lambda: [belt])
        keeper.start()
        try:
            vid = 0
            models = [
                IndexedModel(k + 1, f"m{k}", f"m{k}", "default", "2d", None) for k in range(3)
            ]
            for m in models:  # nine views added one after the other, in one go
                base = textured_rgb(20 + m.id)
                for a in (-10, 0, 10):
                    vid += 1
                    live.add_view(m, vid, 1, live.extract(_turned(base, a), None))
            await asyncio.wait_for(keeper.settled(), TIMEOUT_S)
            assert keeper.runs == 1
            assert [j.kind for j in jobs.list()] == ["threshold"]
            async with db.session() as s:
                first = await latest_settings(s)
            assert first is not None and first.chosen_by == "auto"
            assert first.global_threshold >= THRESHOLD_FLOOR
            assert first.detail["views"] == 9 and first.detail["signature"]
            assert first.detail["negatives"] == 1  # the teach background is an impostor too
            # Nothing changed: a poke is a quick skip, not a second choice.
            keeper.changed()
            await asyncio.wait_for(keeper.settled(), TIMEOUT_S)
            assert keeper.runs == 2 and keeper.last is not None and keeper.last["skipped"]
            # A rename changes what the threshold is chosen from: chosen again.
            live.put_model(IndexedModel(1, "renamed", "m0", "default", "2d", None))
            await asyncio.wait_for(keeper.settled(), TIMEOUT_S)
            assert keeper.runs == 3 and not keeper.last["skipped"]
            async with db.session() as s:
                again = await latest_settings(s)
            assert again is not None and again.id != first.id
            assert "renamed" in again.detail["per_model"]
            # A deleted view too.
            live.remove_view(vid)
            await asyncio.wait_for(keeper.settled(), TIMEOUT_S)
            assert keeper.runs == 4 and not keeper.last["skipped"]
            assert keeper.last["stored"] is True
        finally:
            await keeper.stop()
            await db.dispose()

    asyncio.run(run())


def test_a_teach_holds_the_keeper_and_chooses_once_through_it(tmp_path):
    """While a teach runs the keeper waits (its views are about to change); the teach's
    choice is the keeper's (the same negatives and signature), so the keeper's own round
    after it is a skip, not the same work again."""
    settings = make_settings(tmp_path)
    migrate(settings)

    async def run() -> None:
        db = Database(settings.database_url)
        live = LiveIndex()
        jobs = JobManager()
        belt = np.full((240, 320, 3), 90, np.uint8)
        keeper = ThresholdKeeper(db, live, jobs, quiet_s=0.0, backgrounds=lambda: [belt])
        keeper.start()
        try:
            models = [
                IndexedModel(k + 1, f"m{k}", f"m{k}", "default", "2d", None) for k in range(2)
            ]
            messages: list[str] = []
            async with keeper.holding():
                vid = 0
                for m in models:  # the teach stores its views
                    base = textured_rgb(40 + m.id)
                    for a in (-10, 0, 10):
                        vid += 1
                        live.add_view(m, vid, 1, live.extract(_turned(base, a), None))
                for _ in range(100):  # let the keeper's loop see the change (quiet_s is 0)
                    await asyncio.sleep(0)
                assert keeper.status()["state"] == "waiting" and jobs.list() == []
                # The teach's last change (its model's measured height) right before the
                # choice: notified through the loop, it must not stop the choice.
                live.put_model(IndexedModel(1, "m0", "m0", "default", "2d", None, height_m=0.1))
                outcome = await keeper.choose(lambda f, msg: messages.append(msg))
            assert outcome.stored and not outcome.skipped and outcome.negatives == 1
            assert outcome.threshold is not None and outcome.threshold >= THRESHOLD_FLOOR
            assert any(m.startswith("held-out query") for m in messages), messages
            await asyncio.wait_for(keeper.settled(), TIMEOUT_S)
            assert [j.kind for j in jobs.list()] == ["threshold"]
            assert keeper.last is not None and keeper.last["skipped"] is True
            async with db.session() as s:
                row = await latest_settings(s)
            assert row is not None and row.global_threshold == outcome.threshold
            # A second choice from the same data is told from the settings in force.
            again = await keeper.choose(lambda f, msg: None)
            assert again.skipped and not again.stored and again.in_force == outcome.threshold
        finally:
            await keeper.stop()
            await db.dispose()

    asyncio.run(run())


def _settled(client, headers, runs: int) -> dict:
    """The keeper's status once it has run at least ``runs`` times and is idle."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < TIMEOUT_S:
        s = client.get("/api/recognition/threshold", headers=headers).json()
        if s["state"] == "idle" and s["runs"] >= runs:
            return s
        time.sleep(0.05)
    raise AssertionError(f"the threshold keeper did not settle: {s}")


@pytest.fixture
def follow_client(tmp_path):
    settings = make_settings(tmp_path, threshold_follow=True, threshold_quiet_s=0.0)
    migrate(settings)
    tokens = make_tokens(settings)
    headers = {r: {"Authorization": f"Bearer {t}"} for r, t in tokens.items()}
    with TestClient(create_app(settings)) as client:
        yield client, headers


def test_one_model_gets_a_threshold_from_negatives(follow_client):
    client, headers = follow_client
    eng = headers["engineer"]
    m = client.post("/api/models", json={"name": "solo", "kind": "2d"}, headers=eng).json()
    base = textured_rgb(31)
    files = [("images", (f"v{a}.png", png_bytes(_turned(base, a)), "image/png"))
             for a in (-12, 0, 12)]  # fmt: skip
    assert client.post(f"/api/models/{m['id']}/views", files=files, headers=eng).status_code == 201
    s = _settled(client, headers["viewer"], 1)
    assert s["last"]["stored"] is False and s["settings"]["chosen_by"] == "default"
    assert "negative images" in " ".join(s["last"]["advice"])
    # Negatives: the empty belt and other things; one upload, one recomputation.
    belt = np.full((240, 320, 3), 90, np.uint8)
    negs = [("belt.png", png_bytes(belt))] + [
        (f"other{k}.png", png_bytes(textured_rgb(60 + k))) for k in range(4)
    ]
    r = client.post("/api/recognition/negatives", headers=eng, data={"note": "belt and clutter"},
                    files=[("images", (n, b, "image/png")) for n, b in negs])  # fmt: skip
    assert r.status_code == 201 and r.json()["count"] == 5, r.text
    s = _settled(client, headers["viewer"], 2)
    chosen = s["settings"]
    assert chosen["chosen_by"] == "auto", s
    assert chosen["global_threshold"] >= THRESHOLD_FLOOR
    assert chosen["detail"]["negatives"] == 5
    # Five negatives cannot bound a 1 % false-accept rate: the product says what to add.
    advice = " ".join(chosen["detail"]["advice"])
    assert "Add impostors" in advice and "99 impostor scores" in advice
    listed = client.get("/api/recognition/negatives", headers=headers["viewer"]).json()
    assert listed["count"] == 5 and listed["data"][0]["note"] == "belt and clutter"
    # The known object is recognised against that threshold; the clutter is not.
    q = png_bytes(_turned(base, 6))
    res = client.post(
        "/api/recognition/recognise",
        headers=headers["viewer"],
        files=[
            ("images", ("q.png", q, "image/png")),
            ("images", ("o.png", png_bytes(textured_rgb(77)), "image/png")),
        ],
    )
    assert [d["decision"] for d in res.json()["data"]] == ["recognized", "unknown"]  # fmt: skip
    # Deleting a negative recomputes too; viewers may not delete.
    nid = listed["data"][0]["id"]
    assert (
        client.delete(f"/api/recognition/negatives/{nid}", headers=headers["viewer"]).status_code
        == 403
    )
    assert client.delete(f"/api/recognition/negatives/{nid}", headers=eng).status_code == 204
    s = _settled(client, headers["viewer"], 3)
    assert s["settings"]["detail"]["negatives"] == 4
    assert client.delete(f"/api/recognition/negatives/{nid}", headers=eng).status_code == 404


def test_views_imported_by_the_cli_are_followed_by_the_running_cell(tmp_path):
    """``visioncell models import`` writes to the database from another process; the cell's
    index sync picks the views up and the threshold follows them."""
    import os
    import subprocess
    import sys

    import httpx

    from tests.utils.factories import TEST_SECRET
    from tests.utils.servers import run_uvicorn

    settings = make_settings(tmp_path, threshold_follow=True, threshold_quiet_s=0.0,
                             index_poll_s=0.2)  # fmt: skip
    migrate(settings)
    viewer = make_tokens(settings)["viewer"]
    env = {**os.environ, "VISIONCELL_DATABASE_URL": settings.database_url,
           "VISIONCELL_SECRET_KEY": TEST_SECRET}  # fmt: skip
    with run_uvicorn(create_app(settings)) as srv:
        for name, seed in (("left", 51), ("right", 52)):
            folder = tmp_path / name
            folder.mkdir()
            for a in (-12, 0, 12):
                img = _turned(textured_rgb(seed), a)
                cv2.imwrite(str(folder / f"top_{a + 20}.png"), cv2.cvtColor(img, cv2.COLOR_RGB2BGR))
            r = subprocess.run(
                [sys.executable, "-m", "backend.cli", "models", "import", name, str(folder),
                 "--kind", "2d"], capture_output=True, text=True, env=env, timeout=TIMEOUT_S,
            )  # fmt: skip
            assert r.returncode == 0, r.stderr
        headers = {"Authorization": f"Bearer {viewer}"}
        t0 = time.monotonic()
        while time.monotonic() - t0 < TIMEOUT_S:
            s = httpx.get(f"{srv.base}/api/recognition/threshold", headers=headers).json()
            if s["state"] == "idle" and s["settings"]["detail"].get("views") == 6:
                break
            time.sleep(0.1)
        assert s["settings"]["chosen_by"] == "auto", s
        assert set(s["settings"]["detail"]["per_model"]) == {"left", "right"}
