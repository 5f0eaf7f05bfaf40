"""/api/models: CRUD, roles, bad input, uploads (size, image bombs, wrong types), the live
index following every change, start-up loading and stale descriptor versions."""

from __future__ import annotations

import asyncio
import math

import cv2
import numpy as np
import pytest
from fastapi.testclient import TestClient
from sqlalchemy import func, select, update

from backend.app import create_app
from backend.db.models import ObjectModel, TrainedView
from backend.db.session import Database
from backend.recognition.images import MAX_IMAGE_BYTES
from tests.utils.models import jpeg_bytes, png_bomb, png_bytes, textured_rgb


def _create(client, headers, **body):
    body = {"name": "wheel-a", "kind": "2d", **body}
    return client.post("/api/models", json=body, headers=headers["engineer"])


def _upload(client, headers, model_id, images, *, viewpoints="1", masks=None, yaws=None):
    files = [("images", (name, data, "application/octet-stream")) for name, data in images]
    for name, data in masks or []:
        files.append(("masks", (name, data, "image/png")))
    form = {"viewpoints": viewpoints}
    if yaws is not None:
        form["yaws"] = yaws
    return client.post(
        f"/api/models/{model_id}/views", files=files, data=form, headers=headers["engineer"]
    )


def _count_rows(settings, table) -> int:
    async def run() -> int:
        db = Database(settings.database_url)
        try:
            async with db.session() as s:
                return int(await s.scalar(select(func.count()).select_from(table)))
        finally:
            await db.dispose()

    return asyncio.run(run())


def _live(client):
    return client.app.state.runtime.live_index


# -- CRUD -----------------------------------------------------------------------------------


def test_create_read_update_delete(client, headers):
    r = _create(client, headers, part="wheel", sitting_base="rim-down", threshold=0.4)
    assert r.status_code == 201, r.text
    m = r.json()
    assert m["name"] == "wheel-a" and m["part"] == "wheel" and m["sitting_base"] == "rim-down"
    assert m["kind"] == "2d" and m["threshold"] == 0.4 and m["views"] == 0
    r = _create(client, headers, name="bracket-flat", kind="3d")
    assert r.status_code == 201
    assert r.json()["part"] == "bracket-flat"  # the part defaults to the name

    r = client.get("/api/models", headers=headers["viewer"])
    assert r.status_code == 200
    body = r.json()
    assert body["count"] == 2 and [d["name"] for d in body["data"]] == ["bracket-flat", "wheel-a"]
    r = client.get("/api/models?limit=1&offset=1", headers=headers["viewer"])
    assert r.json()["count"] == 2 and [d["name"] for d in r.json()["data"]] == ["wheel-a"]
    r = client.get("/api/models?part=wheel", headers=headers["viewer"])
    assert [d["name"] for d in r.json()["data"]] == ["wheel-a"]

    r = client.get(f"/api/models/{m['id']}", headers=headers["viewer"])
    assert r.status_code == 200 and r.json()["name"] == "wheel-a"

    r = client.patch(
        f"/api/models/{m['id']}",
        json={"name": "wheel-b", "kind": "3d", "threshold": None},
        headers=headers["engineer"],
    )
    assert r.status_code == 200, r.text
    assert r.json()["name"] == "wheel-b" and r.json()["kind"] == "3d"
    assert r.json()["threshold"] is None and r.json()["part"] == "wheel"

    r = client.delete(f"/api/models/{m['id']}", headers=headers["engineer"])
    assert r.status_code == 204
    r = client.get(f"/api/models/{m['id']}", headers=headers["viewer"])
    assert r.status_code == 404
    assert r.json() == {"error": "not_found", "detail": f"no object model with id {m['id']}"}


def test_duplicate_names_conflict_and_leave_one_row(client, headers, settings):
    assert _create(client, headers).status_code == 201
    r = _create(client, headers)
    assert r.status_code == 409
    assert r.json()["error"] == "conflict" and "'wheel-a' exists already" in r.json()["detail"]
    other = _create(client, headers, name="wheel-c").json()
    r = client.patch(
        f"/api/models/{other['id']}", json={"name": "wheel-a"}, headers=headers["engineer"]
    )
    assert r.status_code == 409
    assert _count_rows(settings, ObjectModel) == 2
    assert client.get(f"/api/models/{other['id']}", headers=headers["viewer"]).json()["name"] == (
        "wheel-c"
    )


def test_roles(client, headers):
    assert client.get("/api/models").status_code == 401
    for role in ("viewer", "operator"):
        r = client.post("/api/models", json={"name": "x", "kind": "2d"}, headers=headers[role])
        assert r.status_code == 403, role
        assert r.json()["error"] == "forbidden" and "engineer" in r.json()["detail"]
    m = _create(client, headers).json()
    for method, path in (
        ("patch", f"/api/models/{m['id']}"),
        ("delete", f"/api/models/{m['id']}"),
        ("delete", f"/api/models/{m['id']}/views/1"),
        ("post", f"/api/models/{m['id']}/teach"),
    ):
        kw = {"json": {}} if method in ("patch", "post") else {}
        r = getattr(client, method)(path, headers=headers["operator"], **kw)
        assert r.status_code == 403, (method, path)
    assert client.get(f"/api/models/{m['id']}/views", headers=headers["viewer"]).status_code == 200


@pytest.mark.shared_app  # refused: nothing stored, nothing moved
@pytest.mark.parametrize(
    ("body", "fragment"),
    [
        ({"name": "has space", "kind": "2d"}, "name"),
        ({"name": "", "kind": "2d"}, "name"),
        ({"name": "x" * 65, "kind": "2d"}, "name"),
        ({"name": "a", "kind": "4d"}, "kind"),
        ({"name": "a"}, "kind"),
        ({"name": "a", "kind": "2d", "threshold": 1.5}, "threshold"),
        ({"name": "a", "kind": "2d", "threshold": -0.1}, "threshold"),
        ({"name": "a", "kind": "2d", "threshold": True}, "threshold"),
        ({"name": "a", "kind": "2d", "threshold": "0.5"}, "threshold"),
        ({"name": 7, "kind": "2d"}, "name"),
        ({"name": "a", "kind": "2d", "colour": "red"}, "colour"),
        ({"name": "a", "kind": "2d", "part": "no/slash"}, "part"),
        ({"name": "a", "kind": "2d", "description": "x" * 2001}, "description"),
    ],
)
def test_bad_model_bodies_are_refused(client, headers, settings, body, fragment):
    r = client.post("/api/models", json=body, headers=headers["engineer"])
    assert r.status_code == 422, r.text
    assert r.json()["error"] == "validation_error" and fragment in r.json()["detail"]
    assert _count_rows(settings, ObjectModel) == 0


def test_non_finite_threshold_and_bad_ids(client, headers):
    r = client.post(
        "/api/models",
        content=b'{"name": "a", "kind": "2d", "threshold": NaN}',
        headers={**headers["engineer"], "Content-Type": "application/json"},
    )
    assert r.status_code == 422
    m = _create(client, headers).json()
    r = client.patch(f"/api/models/{m['id']}", json={"name": None}, headers=headers["engineer"])
    assert r.status_code == 422 and "may not be null" in r.json()["detail"]
    for bad in ("0", "-1", str(2**31), "abc", "1.5"):
        r = client.get(f"/api/models/{bad}", headers=headers["viewer"])
        assert r.status_code == 422, bad
        assert r.json()["error"] == "validation_error"
    assert client.get(f"/api/models/{2**31 - 1}", headers=headers["viewer"]).status_code == 404


# -- uploads and the live index --------------------------------------------------------------


def test_upload_lists_views_with_thumbnails_and_indexes_them(client, headers, settings):
    m = _create(client, headers, kind="3d").json()
    a, b = textured_rgb(1), textured_rgb(2)
    mask = np.zeros(a.shape[:2], np.uint8)
    mask[40:200, 60:260] = 255
    r = _upload(
        client,
        headers,
        m["id"],
        [("top.png", png_bytes(a)), ("side.jpg", jpeg_bytes(b))],
        viewpoints="[1, 2]",
        masks=[
            ("m1.png", png_bytes(np.dstack([mask] * 3))),
            ("m2.png", png_bytes(np.full_like(b, 255))),
        ],
        yaws=f"[0.0, {math.pi / 2}]",
    )
    assert r.status_code == 201, r.text
    views = r.json()["data"]
    assert [v["viewpoint"] for v in views] == [1, 2]
    assert all(v["indexed"] and v["stale"] is None and v["keypoints"] >= 3 for v in views)
    assert views[1]["yaw_rad"] == pytest.approx(math.pi / 2)
    assert views[0]["descriptor"]["kind"] == "sift" and views[0]["source"] == "upload"
    assert len(_live(client)) == 2

    listed = client.get(f"/api/models/{m['id']}/views", headers=headers["viewer"]).json()
    assert listed["count"] == 2
    thumb = client.get(listed["data"][0]["thumbnail_url"], headers=headers["viewer"])
    assert thumb.status_code == 200 and thumb.headers["content-type"] == "image/jpeg"
    t = cv2.imdecode(np.frombuffer(thumb.content, np.uint8), cv2.IMREAD_COLOR)
    assert max(t.shape[:2]) == 160
    full = client.get(listed["data"][0]["image_url"], headers=headers["viewer"])
    back = cv2.cvtColor(cv2.imdecode(np.frombuffer(full.content, np.uint8), 1), cv2.COLOR_BGR2RGB)
    assert np.array_equal(back, a)
    got = client.get(listed["data"][0]["mask_url"], headers=headers["viewer"])
    assert np.array_equal(cv2.imdecode(np.frombuffer(got.content, np.uint8), 0) > 127, mask > 0)
    # Features were extracted inside the mask only.
    with _live(client).reading() as index:
        xy = index.view(views[0]["id"]).features.keypoints.xy
    assert xy[:, 0].min() >= 55 and xy[:, 0].max() <= 265 and xy[:, 1].min() >= 35

    model = client.get(f"/api/models/{m['id']}", headers=headers["viewer"]).json()
    assert model["views"] == 2 and model["indexed_views"] == 2
    assert model["views_per_viewpoint"] == {"1": 1, "2": 1}

    # Deleting a view takes it out of the index; deleting the model takes the rest.
    r = client.delete(f"/api/models/{m['id']}/views/{views[0]['id']}", headers=headers["engineer"])
    assert r.status_code == 204
    assert len(_live(client)) == 1 and not _live(client).has_view(views[0]["id"])
    r = client.delete(f"/api/models/{m['id']}/views/{views[0]['id']}", headers=headers["engineer"])
    assert r.status_code == 404
    assert client.delete(f"/api/models/{m['id']}", headers=headers["engineer"]).status_code == 204
    assert len(_live(client)) == 0
    assert _count_rows(settings, TrainedView) == 0


def test_rename_follows_into_the_index(client, headers):
    m = _create(client, headers).json()
    _upload(client, headers, m["id"], [("a.png", png_bytes(textured_rgb(3)))])
    client.patch(
        f"/api/models/{m['id']}",
        json={"name": "wheel-z", "part": "rims"},
        headers=headers["engineer"],
    )
    with _live(client).reading() as index:
        assert index.models == ("wheel-z",)
        assert index.views[0].part == "rims"


def test_index_is_rebuilt_from_the_database_at_start_up(settings, tokens, headers):
    with TestClient(create_app(settings)) as c:
        m = _create(c, headers).json()
        r = _upload(
            c,
            headers,
            m["id"],
            [("a.png", png_bytes(textured_rgb(4))), ("b.png", png_bytes(textured_rgb(5)))],
        )
        assert r.status_code == 201
        ids = [v["id"] for v in r.json()["data"]]
    with TestClient(create_app(settings)) as c:
        live = _live(c)
        assert len(live) == 2 and all(live.has_view(i) for i in ids)
        with live.reading() as index:
            assert index.models == ("wheel-a",)


def test_stale_descriptor_version_is_refused_then_reextracted(settings, tokens, headers):
    with TestClient(create_app(settings)) as c:
        m = _create(c, headers).json()
        vid = _upload(c, headers, m["id"], [("a.png", png_bytes(textured_rgb(6)))]).json()["data"][
            0
        ]["id"]

    async def age() -> None:
        db = Database(settings.database_url)
        try:
            async with db.session() as s:
                await s.execute(update(TrainedView).values(descriptor_version="opencv-3.4.0"))
        finally:
            await db.dispose()

    asyncio.run(age())
    with TestClient(create_app(settings)) as c:
        live = _live(c)
        assert len(live) == 0 and vid in live.stale
        view = c.get(f"/api/models/{m['id']}/views", headers=headers["viewer"]).json()["data"][0]
        assert view["indexed"] is False
        assert "opencv-3.4.0" in view["stale"] and "visioncell models reextract" in view["stale"]
        from backend.recognition.views import reextract_views

        n = c.portal.call(lambda: reextract_views(c.app.state.runtime.database, live))
        assert n == 1 and live.has_view(vid) and not live.stale


def test_upload_refuses_bad_files_and_keeps_nothing(client, headers, settings):
    m = _create(client, headers).json()
    good = ("good.png", png_bytes(textured_rgb(7)))
    cases = [
        ([good, ("bomb.png", png_bomb())], 413, "too_large", "60000 x 60000"),
        ([good, ("big.png", b"\x89PNG" + b"\0" * MAX_IMAGE_BYTES)], 413, "too_large", "bytes"),
        (
            [good, ("notes.png", b"GIF89a" + b"\0" * 100)],
            415,
            "unsupported_media_type",
            "not a PNG",
        ),
        (
            [good, ("cut.png", png_bytes(textured_rgb(8))[:200])],
            415,
            "unsupported_media_type",
            "decode",
        ),
        (
            [good, ("flat.png", png_bytes(np.full((100, 100, 3), 90, np.uint8)))],
            422,
            "invalid_value",
            "features",
        ),
        (
            [good, ("tiny.png", png_bytes(np.zeros((8, 8, 3), np.uint8)))],
            422,
            "invalid_value",
            "8 x 8",
        ),
    ]
    for images, code, error, fragment in cases:
        r = _upload(client, headers, m["id"], images)
        assert r.status_code == code, (images[1][0], r.text)
        assert r.json()["error"] == error and fragment in r.json()["detail"], r.json()
        assert images[1][0] in r.json()["detail"] or code == 413
    for viewpoints, fragment in (
        ("4", "viewpoints"),
        ("[1]", "one value per image"),
        ("true", "finite"),
        ("1.5", "1, 2 or 3"),
    ):
        r = _upload(client, headers, m["id"], [good, good], viewpoints=viewpoints)
        assert r.status_code == 422 and fragment in r.json()["detail"], (viewpoints, r.text)
    r = _upload(client, headers, m["id"], [good], yaws="[Infinity]")
    assert r.status_code == 422
    r = _upload(
        client,
        headers,
        m["id"],
        [good],
        masks=[("m.png", png_bytes(np.zeros((240, 320, 3), np.uint8)))],
    )
    assert r.status_code == 422 and "empty" in r.json()["detail"]
    r = _upload(
        client,
        headers,
        m["id"],
        [good],
        masks=[("m.png", png_bytes(np.zeros((24, 32, 3), np.uint8) + 255))],
    )
    assert r.status_code == 422 and "32 x 24" in r.json()["detail"]
    assert _count_rows(settings, TrainedView) == 0 and len(_live(client)) == 0
    r = _upload(client, headers, 999, [good])
    assert r.status_code == 404
