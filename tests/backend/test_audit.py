"""The audit trail: every kind of change is recorded with who, when, old and new value and
reason, in the change's own transaction; refused changes leave no row; the trail is read
only, for engineers; filters and pages; no secret ever lands in it; SQLite and PostgreSQL."""

from __future__ import annotations

import asyncio
import json
import os
import subprocess
import sys
from datetime import UTC, datetime, timedelta

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import func, select

from backend import audit
from backend.app import create_app
from backend.db.models import ApiToken, AuditEntry, Calibration, CalibrationKind, ObjectModel
from backend.db.session import Database
from backend.recognition import thresholds
from backend.recognition.views import reextract_views
from tests.utils.factories import TEST_SECRET, make_settings, make_tokens, migrate
from tests.utils.models import png_bytes, textured_rgb
from vision.errors import InvalidInput


def _rows(settings, **filters) -> list[AuditEntry]:
    async def run() -> list[AuditEntry]:
        db = Database(settings.database_url)
        try:
            async with db.session() as s:
                rows, _ = await audit.query(s, limit=500, **filters)
                return rows
        finally:
            await db.dispose()

    return asyncio.run(run())


def _count(settings, table=AuditEntry) -> int:
    async def run() -> int:
        db = Database(settings.database_url)
        try:
            async with db.session() as s:
                return int(await s.scalar(select(func.count()).select_from(table)))
        finally:
            await db.dispose()

    return asyncio.run(run())


def _create(client, headers, **body):
    return client.post(
        "/api/models", json={"name": "wheel-a", "kind": "2d", **body}, headers=headers["engineer"]
    )


def _upload(client, headers, model_id, seeds, *, reason=None):
    files = [("images", (f"v{s}.png", png_bytes(textured_rgb(s)), "image/png")) for s in seeds]
    data = {"viewpoints": "1"}
    if reason is not None:
        data["reason"] = reason
    return client.post(
        f"/api/models/{model_id}/views", files=files, data=data, headers=headers["engineer"]
    )


def _trail(client, headers, query=""):
    r = client.get(f"/api/audit{query}", headers=headers["engineer"])
    assert r.status_code == 200, r.text
    return r.json()


# -- roles and read-only ---------------------------------------------------------------------


def test_only_engineers_read_the_trail(client, headers):
    assert client.get("/api/audit").status_code == 401
    for role in ("viewer", "operator"):
        r = client.get("/api/audit", headers=headers[role])
        assert r.status_code == 403 and r.json()["error"] == "forbidden"
    body = _trail(client, headers)
    assert body == {"data": [], "count": 0}


@pytest.mark.parametrize("method", ["POST", "PUT", "PATCH", "DELETE"])
@pytest.mark.parametrize("path", ["/api/audit", "/api/audit/1"])
def test_no_endpoint_writes_the_trail(client, headers, method, path):
    assert _create(client, headers).status_code == 201
    before = _count(client.app.state.settings)
    r = client.request(method, path, json={"reason": "x"}, headers=headers["engineer"])
    assert r.status_code in (404, 405), (method, path, r.status_code)
    assert set(r.json()) == {"error", "detail"}
    assert _count(client.app.state.settings) == before


# -- models and thresholds -------------------------------------------------------------------


def test_model_create_update_delete_and_its_threshold_are_recorded(client, headers, settings):
    t0 = datetime.now(UTC)
    r = _create(client, headers, threshold=0.4, reason="new wheel type")
    assert r.status_code == 201, r.text
    mid = r.json()["id"]
    r = client.patch(
        f"/api/models/{mid}",
        json={"threshold": 0.55, "description": "rim", "reason": "too many unknowns"},
        headers=headers["engineer"],
    )
    assert r.status_code == 200, r.text
    r = client.patch(f"/api/models/{mid}", json={"threshold": None}, headers=headers["engineer"])
    assert r.status_code == 200
    r = client.delete(f"/api/models/{mid}?reason=obsolete", headers=headers["engineer"])
    assert r.status_code == 204

    rows = list(reversed(_rows(settings, entity_id=str(mid))))
    got = [(e.kind, e.action) for e in rows]
    assert got == [
        ("model", "create"),
        ("threshold", "set"),
        ("model", "update"),
        ("threshold", "set"),
        ("model", "update"),
        ("threshold", "clear"),
        ("model", "delete"),
    ]
    for e in rows:
        assert e.actor == "test-engineer" and e.actor_role == "engineer"
        assert t0 - timedelta(seconds=1) <= e.at <= datetime.now(UTC)
        assert e.at.tzinfo is not None and e.at.utcoffset() == timedelta(0)
    create, t_create, update, t_update, _, t_clear, delete = rows
    assert create.old is None and create.new["name"] == "wheel-a" and create.new["kind"] == "2d"
    assert create.reason == "new wheel type" and t_create.new == {
        "model": "wheel-a",
        "threshold": 0.4,
    }
    assert update.old["threshold"] == 0.4 and update.new["threshold"] == 0.55
    assert update.old["description"] == "" and update.new["description"] == "rim"
    assert update.reason == t_update.reason == "too many unknowns"
    assert t_update.old["threshold"] == 0.4 and t_update.new["threshold"] == 0.55
    assert t_clear.new["threshold"] is None and t_clear.reason == ""
    assert delete.old["name"] == "wheel-a" and delete.new is None and delete.reason == "obsolete"


def test_refused_changes_leave_no_row(client, headers, settings):
    mid = _create(client, headers).json()["id"]
    other = _create(client, headers, name="wheel-b").json()["id"]
    before = _count(settings)
    eng = headers["engineer"]
    refused = [
        _create(client, headers),  # name taken: 409
        client.patch(f"/api/models/{other}", json={"name": "wheel-a"}, headers=eng),  # 409
        client.patch(f"/api/models/{mid}", json={"threshold": 1.5}, headers=eng),  # 422
        client.patch(f"/api/models/{mid}", json={"threshold": True}, headers=eng),  # 422
        client.patch(f"/api/models/{mid}", json={"reason": "x" * 501}, headers=eng),  # 422
        client.patch("/api/models/999", json={"threshold": 0.3}, headers=eng),  # 404
        client.patch(f"/api/models/{mid}", json={"threshold": 0.3}, headers=headers["operator"]),
        client.delete("/api/models/999", headers=eng),  # 404
        client.put("/api/recognition/settings", json={"global_threshold": 2.0}, headers=eng),
        client.post("/api/users", json={"name": "test-viewer", "role": "viewer"}, headers=eng),
        client.delete("/api/users/test-engineer", headers=eng),  # yourself: 409
        client.patch("/api/users/test-engineer", json={"role": "viewer"}, headers=eng),  # 409
        client.post("/api/calibration/calibrations/9/activate", headers=eng),  # 404
        client.delete(f"/api/models/{mid}/views/12345", headers=eng),  # 404
    ]
    assert [r.status_code for r in refused] == [
        409, 409, 422, 422, 422, 404, 403, 404, 422, 409, 409, 409, 404, 404,
    ]  # fmt: skip
    assert _count(settings) == before
    r = client.get(f"/api/models/{mid}", headers=eng)
    assert r.json()["threshold"] is None and r.json()["name"] == "wheel-a"


def test_a_change_whose_audit_row_fails_is_not_made(client, headers, settings, monkeypatch):
    """The row is written in the change's transaction: if it cannot be, nothing changes."""
    mid = _create(client, headers).json()["id"]
    n_models, n_rows = _count(settings, ObjectModel), _count(settings)

    def broken(*_a, **_k):
        raise InvalidInput("audit trail unavailable")

    monkeypatch.setattr(audit, "record", broken)
    eng = headers["engineer"]
    assert _create(client, headers, name="wheel-c").status_code == 422
    assert client.patch(f"/api/models/{mid}", json={"threshold": 0.3}, headers=eng).status_code == (
        422
    )
    assert client.delete(f"/api/models/{mid}", headers=eng).status_code == 422
    r = client.put("/api/recognition/settings", json={"global_threshold": 0.7}, headers=eng)
    assert r.status_code == 422
    r = client.post("/api/users", json={"name": "nobody", "role": "viewer"}, headers=eng)
    assert r.status_code == 422
    monkeypatch.undo()
    assert _count(settings, ObjectModel) == n_models and _count(settings) == n_rows
    assert client.get(f"/api/models/{mid}", headers=eng).json()["threshold"] is None
    assert client.get("/api/recognition/settings", headers=eng).json()["chosen_by"] == "default"
    names = [u["name"] for u in client.get("/api/users", headers=eng).json()["data"]]
    assert "nobody" not in names


def test_global_threshold_by_hand_and_automatic(client, headers, settings):
    eng = headers["engineer"]
    # Automatic: two models with views, then the rule chooses (as after a teach).
    for name, seeds in (("wheel-a", (1, 2, 3)), ("bracket", (11, 12, 13))):
        mid = _create(client, headers, name=name).json()["id"]
        assert _upload(client, headers, mid, seeds).status_code == 201

    async def recompute():
        db = Database(settings.database_url)
        try:
            return await thresholds.recompute(db, client.app.state.runtime.live_index)
        finally:
            await db.dispose()

    outcome = asyncio.run(recompute())
    assert outcome.stored, outcome.reason
    (auto,) = _rows(settings, kind="threshold", entity_id="global")
    assert auto.actor == "system" and auto.actor_role == "system" and auto.action == "auto"
    assert auto.old is None and auto.new["chosen_by"] == "auto"
    assert auto.new["global_threshold"] == pytest.approx(outcome.threshold)
    assert set(auto.new["per_model"]) == {"wheel-a", "bracket"}
    assert auto.reason and auto.reason == outcome.reason[: audit.MAX_REASON_LENGTH]
    assert "genuine" not in auto.new  # the score distributions stay in recognition_settings

    r = client.put(
        "/api/recognition/settings",
        json={"global_threshold": 0.62, "reason": "line trial"},
        headers=eng,
    )
    assert r.status_code == 200, r.text
    manual, _ = _rows(settings, kind="threshold", entity_id="global")
    assert manual.actor == "test-engineer" and manual.action == "set"
    assert manual.old["chosen_by"] == "auto"
    assert manual.old["global_threshold"] == pytest.approx(outcome.threshold)
    assert manual.new == {"global_threshold": 0.62, "chosen_by": "manual"}
    assert manual.reason == "line trial"
    # The manual threshold stays: the automatic rule now writes nothing, so records nothing.
    assert not asyncio.run(recompute()).stored
    assert len(_rows(settings, kind="threshold", entity_id="global")) == 2

    # Null hands the threshold back to the automatic rule: the last automatic choice is in
    # force again (audited), and the next recompute writes a new automatic row.
    for bad in ({}, {"global_threshold": "auto"}, {"global_threshold": -0.1}):
        r = client.put("/api/recognition/settings", json=bad, headers=eng)
        assert r.status_code == 422, (bad, r.text)
        assert r.json()["error"] and r.json()["detail"]
    r = client.put("/api/recognition/settings", json={"global_threshold": None},
                   headers=headers["operator"])  # fmt: skip
    assert r.status_code == 403
    r = client.put("/api/recognition/settings",
                   json={"global_threshold": None, "reason": "trial over"}, headers=eng)  # fmt: skip
    assert r.status_code == 200, r.text
    assert r.json()["chosen_by"] == "auto"
    assert r.json()["global_threshold"] == pytest.approx(outcome.threshold)
    back, _, _ = _rows(settings, kind="threshold", entity_id="global")
    assert back.actor == "test-engineer" and back.action == "automatic"
    assert back.old == {"global_threshold": 0.62, "chosen_by": "manual"}
    assert back.new["chosen_by"] == "auto" and set(back.new["per_model"]) == {"wheel-a", "bracket"}
    assert back.reason == "trial over"
    got = client.get("/api/recognition/settings", headers=eng).json()
    assert got["chosen_by"] == "auto" and got["global_threshold"] == pytest.approx(
        outcome.threshold
    )
    # Already automatic: null again changes nothing and records nothing.
    r = client.put("/api/recognition/settings", json={"global_threshold": None}, headers=eng)
    assert r.status_code == 200 and r.json()["chosen_by"] == "auto"
    assert len(_rows(settings, kind="threshold", entity_id="global")) == 3
    assert asyncio.run(recompute()).stored
    assert _rows(settings, kind="threshold", entity_id="global")[0].action == "auto"


def test_global_threshold_back_to_automatic_without_a_choice_is_the_default(client, headers, settings):  # fmt: skip
    eng = headers["engineer"]
    assert client.put("/api/recognition/settings", json={"global_threshold": 0.7},
                      headers=eng).status_code == 200  # fmt: skip
    r = client.put("/api/recognition/settings", json={"global_threshold": None}, headers=eng)
    assert r.status_code == 200, r.text
    assert r.json()["chosen_by"] == "default" and r.json()["global_threshold"] == 0.5
    back, _ = _rows(settings, kind="threshold", entity_id="global")
    assert back.action == "automatic" and back.new == {
        "global_threshold": 0.5,
        "chosen_by": "default",
    }


# -- trained views ---------------------------------------------------------------------------


def test_views_added_deleted_and_reextracted_are_recorded(client, headers, settings):
    mid = _create(client, headers).json()["id"]
    r = _upload(client, headers, mid, (1, 2), reason="first images")
    assert r.status_code == 201, r.text
    ids = [v["id"] for v in r.json()["data"]]
    added = list(reversed(_rows(settings, kind="view")))
    assert [(e.entity_id, e.action) for e in added] == [(str(i), "add") for i in ids]
    for e in added:
        assert e.old is None and e.new["model_id"] == mid and e.new["model"] == "wheel-a"
        assert e.new["source"] == "upload" and e.new["viewpoint"] == 1
        assert e.new["keypoints"] > 0 and e.reason == "first images"
        assert "image_png" not in e.new and "features" not in e.new

    r = client.delete(
        f"/api/models/{mid}/views/{ids[0]}?reason=blurred", headers=headers["engineer"]
    )
    assert r.status_code == 204
    (gone,) = _rows(settings, kind="view", entity_id=str(ids[0]), until=None)[:1]
    assert gone.action == "delete" and gone.new is None and gone.old["source"] == "upload"
    assert gone.reason == "blurred"

    async def reextract() -> int:
        db = Database(settings.database_url)
        try:
            live = client.app.state.runtime.live_index
            return await reextract_views(
                db, live, model_id=mid, only_stale=False, by=audit.By(audit.CLI, "new version")
            )
        finally:
            await db.dispose()

    assert asyncio.run(reextract()) == 1
    (re,) = _rows(settings, kind="view", actor="cli")
    assert re.entity_id == str(ids[1]) and re.action == "reextract" and re.actor_role == "cli"
    assert re.old["keypoints"] > 0 and re.new["keypoints"] > 0 and re.reason == "new version"


def test_cli_import_and_remove_are_recorded_as_cli(tmp_path):
    folder = tmp_path / "views"
    folder.mkdir()
    for k in range(2):
        (folder / f"top_{k}.png").write_bytes(png_bytes(textured_rgb(40 + k)))
    url = f"sqlite+aiosqlite:///{tmp_path / 'cli.db'}"
    env = {**os.environ, "VISIONCELL_DATABASE_URL": url, "VISIONCELL_SECRET_KEY": TEST_SECRET}

    def run(*args):
        r = subprocess.run(
            [sys.executable, "-m", "backend.cli", *args],
            capture_output=True,
            text=True,
            env=env,
            timeout=120,
        )
        assert r.returncode == 0, r.stdout + r.stderr
        return r

    run("models", "import", "gear", str(folder), "--kind", "2d")
    run("models", "remove", "gear")
    run("user", "add", "alice", "--role", "operator")
    settings = make_settings(tmp_path, database_url=url)
    rows = list(reversed(_rows(settings)))
    assert {e.actor for e in rows} == {"cli"}
    got = [(e.kind, e.action) for e in rows]
    assert got == [
        ("model", "create"),
        ("view", "add"),
        ("view", "add"),
        ("model", "delete"),
        ("user", "create"),
    ]
    assert {e.new["source"] for e in rows if e.kind == "view"} == {"import"}
    assert rows[-1].new == {"name": "alice", "role": "operator", "token_label": "created"}


# -- calibrations ----------------------------------------------------------------------------


def test_activating_a_calibration_is_recorded(client, headers, settings):
    cell_id = client.app.state.runtime.cell.db_id

    async def add_two() -> list[int]:
        db = Database(settings.database_url)
        try:
            async with db.session() as s:
                rows = [
                    Calibration(
                        cell_id=cell_id,
                        kind=CalibrationKind.intrinsic,
                        parameters={"K": [[500, 0, 160], [0, 500, 120], [0, 0, 1]]},
                        sample_count=8,
                        rms_px=rms,
                    )
                    for rms in (0.31, 0.22)
                ]
                s.add_all(rows)
                await s.flush()
                return [r.id for r in rows]
        finally:
            await db.dispose()

    first, second = asyncio.run(add_two())
    eng = headers["engineer"]
    url = "/api/calibration/calibrations/{}/activate"
    assert client.post(url.format(first), headers=eng).status_code == 200
    r = client.post(url.format(second) + "?reason=new%20lens", headers=eng)
    assert r.status_code == 200, r.text
    assert client.post(url.format(second), headers=eng).status_code == 200  # no change
    assert client.post(url.format(first), headers=headers["operator"]).status_code == 403
    rows = list(reversed(_rows(settings, kind="calibration")))
    assert [(e.entity_id, e.action) for e in rows] == [
        (str(first), "activate"),
        (str(second), "activate"),
    ]
    a, b = rows
    assert a.old == {"cell_id": cell_id, "kind": "intrinsic", "active_id": None}
    assert a.new["active_id"] == first and a.new["rms_px"] == 0.31
    assert b.old["active_id"] == first and b.new["active_id"] == second
    assert b.reason == "new lens" and b.actor == "test-engineer"


# -- users and tokens ------------------------------------------------------------------------


def _all_json(settings) -> str:
    return json.dumps(
        [
            {"old": e.old, "new": e.new, "reason": e.reason, "entity": e.entity_id}
            for e in _rows(settings)
        ]
    )


def test_users_and_tokens_are_recorded_without_secrets(client, headers, settings):
    eng = headers["engineer"]
    r = client.post(
        "/api/users", json={"name": "bob", "role": "viewer", "reason": "night shift"}, headers=eng
    )
    assert r.status_code == 201, r.text
    token, uid = r.json()["token"], r.json()["user"]["id"]
    r = client.patch("/api/users/bob", json={"role": "operator", "reason": "trained"}, headers=eng)
    assert r.status_code == 200 and r.json()["role"] == "operator"
    assert client.patch("/api/users/bob", json={"role": "operator"}, headers=eng).status_code == (
        200
    )  # same role: nothing changes, nothing recorded
    r = client.patch("/api/users/bob", json={"role": "boss"}, headers=eng)
    assert r.status_code == 422
    r = client.patch("/api/users/bob", json={"role": "engineer"}, headers=headers["operator"])
    assert r.status_code == 403
    assert client.delete("/api/users/bob?reason=left", headers=eng).status_code == 200

    rows = list(reversed(_rows(settings, kind="user", entity_id=str(uid))))
    assert [e.action for e in rows] == ["create", "role", "disable"]
    create, role, disable = rows
    assert create.new == {"name": "bob", "role": "viewer", "token_label": "created"}
    assert create.reason == "night shift" and create.actor == "test-engineer"
    assert role.old == {"name": "bob", "role": "viewer"}
    assert role.new == {"name": "bob", "role": "operator"} and role.reason == "trained"
    assert disable.new == {"name": "bob", "disabled": True, "tokens_revoked": 1}
    assert disable.reason == "left"
    assert client.get(
        "/api/users/me", headers={"Authorization": f"Bearer {token}"}
    ).status_code == (401)

    async def hashes() -> list[str]:
        db = Database(settings.database_url)
        try:
            async with db.session() as s:
                return list(await s.scalars(select(ApiToken.token_hash)))
        finally:
            await db.dispose()

    dump = _all_json(settings)
    assert token not in dump and token[:10] not in dump
    assert not any(h in dump for h in asyncio.run(hashes()))


def test_start_up_token_is_recorded_as_system_without_the_token(tmp_path):
    from backend.cli.users import bootstrap_operator

    settings = make_settings(tmp_path)
    migrate(settings)
    first = asyncio.run(bootstrap_operator(settings))
    second = asyncio.run(bootstrap_operator(settings))
    rows = list(reversed(_rows(settings, kind="token")))
    assert [(e.actor, e.action) for e in rows] == [("system", "issue"), ("system", "issue")]
    assert rows[0].new["revoked"] == 0 and rows[1].new["revoked"] == 1
    assert rows[0].new["user"] == "operator" and rows[0].new["label"] == "startup"
    assert rows[0].entity_id != rows[1].entity_id
    dump = _all_json(settings)
    assert first not in dump and second not in dump and first[:10] not in dump


def test_secrets_are_dropped_at_any_depth(settings):
    async def run() -> AuditEntry:
        db = Database(settings.database_url)
        try:
            async with db.session() as s:
                audit.record(
                    s,
                    actor=audit.SYSTEM,
                    kind="token",
                    entity_id=1,
                    action="issue",
                    old=None,
                    new={"token": "vc_x", "a": {"token_hash": "ab", "ok": [1, {"secret": 2}]}},
                    reason=None,
                )
            async with db.session() as s:
                return (await audit.query(s))[0][0]
        finally:
            await db.dispose()

    row = asyncio.run(run())
    assert row.new == {"a": {"ok": [1, {}]}}
    with pytest.raises(InvalidInput, match="kind"):
        audit.record(
            None,  # type: ignore[arg-type]
            actor=audit.SYSTEM,
            kind="inspection",
            entity_id=1,
            action="x",
            old=None,
            new=None,
            reason=None,
        )
    with pytest.raises(InvalidInput, match="500"):
        audit.check_reason("x" * 501)


# -- the query -------------------------------------------------------------------------------


def test_filters_time_range_and_pages(client, headers):
    eng = headers["engineer"]
    ids = [_create(client, headers, name=f"m{k}").json()["id"] for k in range(3)]
    client.patch(f"/api/models/{ids[0]}", json={"threshold": 0.5}, headers=eng)
    everything = _trail(client, headers)
    assert everything["count"] == 5  # 3 creates, 1 update, 1 threshold
    assert [e["id"] for e in everything["data"]] == sorted(
        (e["id"] for e in everything["data"]), reverse=True
    )
    assert _trail(client, headers, "?kind=threshold")["count"] == 1
    assert _trail(client, headers, f"?kind=model&entity_id={ids[0]}")["count"] == 2
    assert _trail(client, headers, "?actor=test-engineer")["count"] == 5
    assert _trail(client, headers, "?actor=cli")["count"] == 0
    page = _trail(client, headers, "?limit=2&offset=1")
    assert page["count"] == 5 and [e["id"] for e in page["data"]] == [
        e["id"] for e in everything["data"][1:3]
    ]
    newest = everything["data"][0]["at"]
    assert _trail(client, headers, "?since=" + newest.replace("+00:00", "Z"))["count"] >= 1
    assert _trail(client, headers, "?until=2000-01-01T00:00:00Z")["count"] == 0
    assert _trail(client, headers, "?since=2000-01-01T00:00:00%2B02:00")["count"] == 5
    for bad in (
        "?kind=inspection",
        "?limit=0",
        "?limit=501",
        "?offset=-1",
        "?since=yesterday",
        "?since=2026-01-01T00:00:00",  # no zone: ambiguous
        "?since=2026-02-01T00:00:00Z&until=2026-01-01T00:00:00Z",
        "?entity_id=" + "9" * 65,
    ):
        r = client.get(f"/api/audit{bad}", headers=eng)
        assert r.status_code == 422, (bad, r.text)
        assert set(r.json()) == {"error", "detail"}


def test_the_trail_on_postgresql(postgres_url, tmp_path):
    settings = make_settings(tmp_path, database_url=postgres_url)
    tokens = make_tokens(settings)
    h = {"Authorization": f"Bearer {tokens['engineer']}"}
    with TestClient(create_app(settings)) as client:
        r = client.post(
            "/api/models", json={"name": "pg", "kind": "3d", "threshold": 0.3}, headers=h
        )
        assert r.status_code == 201, r.text
        r = client.post("/api/models", json={"name": "pg", "kind": "3d"}, headers=h)
        assert r.status_code == 409
        body = client.get("/api/audit?kind=threshold&since=2000-01-01T00:00:00Z", headers=h).json()
        assert body["count"] == 1 and body["data"][0]["new"] == {"model": "pg", "threshold": 0.3}
        assert client.get("/api/audit", headers=h).json()["count"] == 2
