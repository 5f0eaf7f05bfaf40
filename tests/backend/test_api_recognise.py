"""POST /api/recognition/recognise on synthetic models: the answer's shape (decision, every
model against its threshold, outline, 2D pose, stage times), roles, bounds checked before
decoding, and ``store=true`` making inspection rows (source ``upload``) that reports and
exports include, all or none."""

from __future__ import annotations

import asyncio
import csv
import io
import math

import cv2
import numpy as np
import pytest
from fastapi.testclient import TestClient
from sqlalchemy import func, select

from backend.app import create_app
from backend.db.models import Inspection
from backend.db.session import Database
from tests.utils.factories import make_settings, make_tokens, migrate
from tests.utils.models import png_bomb, png_bytes, textured_rgb

URL = "/api/recognition/recognise"


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    """A cell with two models (a, b) of two views each, and a token per role."""
    tmp = tmp_path_factory.mktemp("recognise")
    settings = make_settings(tmp, recognise_max_images=4, max_request_pixels=2_000_000)
    migrate(settings)
    tokens = make_tokens(settings)
    headers = {r: {"Authorization": f"Bearer {t}"} for r, t in tokens.items()}
    with TestClient(create_app(settings)) as client:
        for name, seed in (("a", 11), ("b", 12)):
            m = client.post("/api/models", json={"name": name, "kind": "2d"},
                            headers=headers["engineer"]).json()  # fmt: skip
            img = textured_rgb(seed)
            files = [("images", (f"{name}{k}.png", png_bytes(_turned(img, 8 * k)), "image/png"))
                     for k in range(2)]  # fmt: skip
            r = client.post(
                f"/api/models/{m['id']}/views", files=files, headers=headers["engineer"]
            )
            assert r.status_code == 201, r.text
        yield settings, client, headers


def _turned(rgb: np.ndarray, angle_deg: float, scale: float = 1.0) -> np.ndarray:
    h, w = rgb.shape[:2]
    M = cv2.getRotationMatrix2D((w / 2, h / 2), angle_deg, scale)
    return cv2.warpAffine(rgb, M, (w, h), borderValue=(128, 128, 128))


def _post(client, headers, images, **data):
    files = [("images", (name, blob, "image/png")) for name, blob in images]
    return client.post(URL, files=files, data={k: str(v).lower() for k, v in data.items()},
                       headers=headers)  # fmt: skip


def _rows(settings) -> int:
    async def run() -> int:
        db = Database(settings.database_url)
        try:
            async with db.session() as s:
                return int(await s.scalar(select(func.count()).select_from(Inspection)) or 0)
        finally:
            await db.dispose()

    return asyncio.run(run())


def test_recognises_with_every_score_the_outline_and_the_pose(cell):
    _settings, client, headers = cell
    query = _turned(textured_rgb(11), 20.0, 0.9)
    r = _post(client, headers["viewer"], [("q.png", png_bytes(query)),
                                          ("noise.png", png_bytes(textured_rgb(99)))])  # fmt: skip
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["count"] == 2 and body["threshold"]["chosen_by"] == "default"
    known, other = body["data"]
    assert known["decision"] == "recognized" and known["model"] == "a"
    assert [s["model"] for s in known["scores"]] == ["a", "b"]  # every model, best first
    a = known["scores"][0]
    assert a["score"] > a["threshold"] and a["passed"] is True
    assert known["score"] == a["score"] and known["view_id"] is not None
    # The pose: the view turned by 20 deg (image rows down: -20 deg) at 0.9 of its size,
    # its centre near the image centre (the texture turned about it).
    pose = known["pose"]
    assert abs(math.degrees(pose["angle_rad"]) % 360 - 340) < 9 or abs(
        math.degrees(pose["angle_rad"]) + 20) < 9  # fmt: skip
    assert pose["scale"] == pytest.approx(0.9, abs=0.1)
    assert len(known["outline_px"]) >= 3
    assert set(known["durations"]) == {"decode", "features", "retrieve", "verify", "decide"}
    assert all(v >= 0 for v in known["durations"].values())
    assert other["decision"] == "unknown" and other["model"] is None
    assert all(not s["passed"] for s in other["scores"])
    assert known["inspection_id"] is None


def test_store_needs_the_operator_and_writes_upload_rows(cell):
    settings, client, headers = cell
    before = _rows(settings)
    q = ("q.png", png_bytes(_turned(textured_rgb(12), -15.0)))
    r = _post(client, headers["viewer"], [q], store=True)
    assert r.status_code == 403 and r.json()["error"] == "forbidden", r.text
    assert _rows(settings) == before
    r = _post(client, headers["operator"], [q, q], store=True)
    assert r.status_code == 200, r.text
    ids = [d["inspection_id"] for d in r.json()["data"]]
    assert all(isinstance(i, int) for i in ids) and _rows(settings) == before + 2
    row = client.get(f"/api/inspections/{ids[0]}", headers=headers["viewer"]).json()
    assert row["source"] == "upload" and row["decision"] == "recognized" and row["model"] == "b"
    assert row["viewpoints_visited"] == [1] and row["pose"]["frame"] == "image"
    assert set(row["durations"]) == {"acquire", "features", "match", "decide"}
    assert len(row["images"]) == 1
    img = client.get(row["images"][0], headers=headers["viewer"])
    assert img.status_code == 200 and img.content[:2] == b"\xff\xd8"
    export = client.get("/api/reports/export.csv", headers=headers["viewer"])
    lines = list(csv.DictReader(io.StringIO(export.text)))
    assert {int(x["id"]) for x in lines if x["source"] == "upload"} >= set(ids)
    summary = client.get("/api/reports/summary", headers=headers["viewer"]).json()
    assert summary  # the rows count in the reports like the cell's own


@pytest.mark.parametrize(
    ("files", "data", "status", "fragment"),
    [
        ([("bomb.png", png_bomb())], {}, 413, "60000 x 60000"),
        ([("a.png", b"GIF89a" + b"\0" * 100)], {}, 415, "not a PNG or JPEG"),
        (
            [("a.png", png_bytes(textured_rgb(1, size=(1100, 1000))))] * 2,
            {},
            413,
            "at most 2000000",
        ),
        ([("a.png", png_bytes(textured_rgb(1)))] * 5, {}, 422, "at most 4 images"),
        ([("a.png", png_bytes(textured_rgb(1)))], {"viewpoint": "4"}, 422, "viewpoint"),
        ([("a.png", png_bytes(textured_rgb(1)))], {"region": "1,2,3"}, 422, "region"),
        ([("a.png", png_bytes(textured_rgb(1)))], {"region": "0,0,400,400"}, 422, "leaves"),
        ([("a.png", png_bytes(textured_rgb(1)))], {"region": "0,0,8,8"}, 422, "at least 16"),
        ([("a.png", png_bytes(textured_rgb(1))[:300])], {}, 415, "does not decode"),
    ],
)
def test_bad_requests_are_refused_before_anything_is_stored(cell, files, data, status, fragment):
    settings, client, headers = cell
    before = _rows(settings)
    r = client.post(URL, files=[("images", (n, b, "image/png")) for n, b in files],
                    data={**data, "store": "true"}, headers=headers["operator"])  # fmt: skip
    assert r.status_code == status, r.text
    body = r.json()
    assert set(body) == {"error", "detail"} and fragment in body["detail"], body
    assert _rows(settings) == before


def test_a_region_limits_where_features_are_taken(cell):
    _settings, client, headers = cell
    img = textured_rgb(11)
    whole = _post(client, headers["viewer"], [("q.png", png_bytes(img))]).json()["data"][0]
    corner = _post(client, headers["viewer"], [("q.png", png_bytes(img))],
                   region="0,0,40,40").json()["data"][0]  # fmt: skip
    assert 0 < corner["n_features"] < whole["n_features"]


def test_recognition_needs_a_token(cell):
    _settings, client, _headers = cell
    r = _post(client, {}, [("q.png", png_bytes(textured_rgb(11)))])
    assert r.status_code == 401 and r.json()["error"] == "unauthorized"
