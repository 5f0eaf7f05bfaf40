"""/api/recipes: create, read, change, delete, select; the roles (viewers read, operators
select, engineers change), bad input refused with the JSON error body and nothing stored,
the audit trail of every change, and the options an inspection takes from a recipe."""

from __future__ import annotations

import asyncio
from types import SimpleNamespace

import pytest
from sqlalchemy import func, select, text

from backend.db.models import Recipe as RecipeRow
from backend.db.session import Database
from backend.inspection.options import InspectOptions
from backend.recipes import model as recipe_model
from backend.recipes import service
from vision.errors import InvalidInput, NotFound


def _model(client, headers, name: str) -> None:
    r = client.post("/api/models", json={"name": name, "kind": "2d"}, headers=headers["engineer"])
    assert r.status_code == 201, r.text


def _recipe(client, headers, **body):
    body = {"name": "wheels", "number": 1, **body}
    return client.post("/api/recipes", json=body, headers=headers["engineer"])


#: The cell's layout: the bins the recipes below name (a recipe may name only bins the cell has).
LAYOUT = """
[station]
x_m = 0.8
y_m = 0.0
surface_z_m = 0.45

[[bins]]
name = "bin-x"
parts = ["wheel-a"]
drop_m = [0.31, 0.61, 0.30]

[[bins]]
name = "bin-1"
parts = ["wheel-b"]
drop_m = [0.31, -0.61, 0.30]

[[bins]]
name = "reject"
reject = true
drop_m = [-0.53, -0.51, 0.30]
"""


@pytest.fixture
def settings(settings, tmp_path):
    """The migrated settings of a real cell whose layout file lists three bins."""
    path = tmp_path / "cell.toml"
    path.write_text(LAYOUT)
    return settings.model_copy(update={"cell_layout": path})


def _count(settings) -> int:
    async def run() -> int:
        db = Database(settings.database_url)
        try:
            async with db.session() as s:
                return int(await s.scalar(select(func.count()).select_from(RecipeRow)) or 0)
        finally:
            await db.dispose()

    return asyncio.run(run())


def test_create_read_update_select_delete_and_audit(client, headers):
    _model(client, headers, "wheel-a")
    _model(client, headers, "wheel-b")
    r = _recipe(client, headers, policy="top-only", max_views=1, sort=True, threshold=0.4,
                models=["wheel-a"], bins={"wheel-a": "bin-x"}, reason="first shift")  # fmt: skip
    assert r.status_code == 201, r.text
    a = r.json()
    assert (a["name"], a["number"], a["policy"], a["max_views"], a["sort"], a["threshold"]) == (
        "wheels", 1, "top-only", 1, True, 0.4)  # fmt: skip
    assert a["models"] == ["wheel-a"] and a["bins"] == {"wheel-a": "bin-x"}
    assert a["belt_mode"] is None and a["active"] is False
    b = _recipe(client, headers, name="mixed", number=7).json()

    listed = client.get("/api/recipes", headers=headers["viewer"]).json()
    assert [x["name"] for x in listed["data"]] == ["wheels", "mixed"]  # by number
    assert listed["count"] == 2 and listed["active"] is None

    # A change keeps what it does not name; options merge.
    r = client.patch(f"/api/recipes/{a['id']}", headers=headers["engineer"],
                     json={"threshold": None, "models": ["wheel-a", "wheel-b"], "reason": "both"})  # fmt: skip
    assert r.status_code == 200, r.text
    a2 = r.json()
    assert a2["threshold"] is None and a2["policy"] == "top-only" and a2["sort"] is True
    assert a2["models"] == ["wheel-a", "wheel-b"] and a2["bins"] == {"wheel-a": "bin-x"}

    r = client.post(f"/api/recipes/{b['id']}/activate", headers=headers["operator"], json={})
    assert r.status_code == 200, r.text
    assert r.json()["active"] is True
    r = client.post(f"/api/recipes/{a['id']}/activate", headers=headers["operator"])
    assert r.status_code == 200, r.text
    listed = client.get("/api/recipes", headers=headers["viewer"]).json()
    assert listed["active"]["id"] == a["id"]
    assert [x["active"] for x in listed["data"]] == [True, False]
    assert client.get(f"/api/recipes/{a['id']}", headers=headers["viewer"]).json()["active"]

    # The active recipe cannot go; another can.
    r = client.delete(f"/api/recipes/{a['id']}", headers=headers["engineer"])
    assert r.status_code == 409 and r.json()["error"] == "conflict", r.text
    assert "active" in r.json()["detail"]
    r = client.delete(f"/api/recipes/{b['id']}?reason=unused", headers=headers["engineer"])
    assert r.status_code == 204, r.text
    r = client.get(f"/api/recipes/{b['id']}", headers=headers["viewer"])
    assert r.status_code == 404 and r.json()["error"] == "not_found"

    trail = client.get("/api/audit?kind=recipe&limit=50", headers=headers["engineer"]).json()
    got = [(e["action"], e["entity_id"], e["actor"]) for e in reversed(trail["data"])]
    assert got == [
        ("create", str(a["id"]), "test-engineer"),
        ("create", str(b["id"]), "test-engineer"),
        ("update", str(a["id"]), "test-engineer"),
        ("activate", str(b["id"]), "test-operator"),
        ("activate", str(a["id"]), "test-operator"),
        ("delete", str(b["id"]), "test-engineer"),
    ]
    update = next(e for e in trail["data"] if e["action"] == "update")
    assert update["old"]["threshold"] == 0.4 and update["new"]["threshold"] is None
    assert update["reason"] == "both"
    second = next(
        e for e in trail["data"] if e["action"] == "activate" and e["entity_id"] == str(a["id"])
    )
    assert second["old"]["name"] == "mixed" and second["new"]["name"] == "wheels"


def test_roles(client, headers):
    rid = _recipe(client, headers).json()["id"]
    for role in ("viewer", "operator"):
        r = client.post("/api/recipes", json={"name": "x", "number": 2}, headers=headers[role])
        assert r.status_code == 403 and r.json()["error"] == "forbidden", (role, r.text)
        r = client.patch(f"/api/recipes/{rid}", json={"sort": True}, headers=headers[role])
        assert r.status_code == 403, (role, r.text)
        r = client.delete(f"/api/recipes/{rid}", headers=headers[role])
        assert r.status_code == 403, (role, r.text)
    r = client.post(f"/api/recipes/{rid}/activate", headers=headers["viewer"])
    assert r.status_code == 403 and r.json()["error"] == "forbidden", r.text
    assert client.get("/api/recipes").status_code == 401
    assert client.get("/api/recipes", headers=headers["viewer"]).status_code == 200
    assert client.get("/api/recipes/bins", headers=headers["viewer"]).json()["count"] == 3


@pytest.mark.parametrize(
    ("body", "status", "fragment"),
    [
        ({"number": 0}, 422, "number"),
        ({"number": 10000}, 422, "number"),
        ({"number": True}, 422, "number"),
        ({"name": "bad name"}, 422, "name"),
        ({"name": "x" * 65}, 422, "name"),
        ({"policy": "guess"}, 422, "policy"),
        ({"max_views": 4}, 422, "max_views"),
        ({"threshold": 1.5}, 422, "threshold"),
        ({"belt_mode": "fast"}, 422, "belt_mode"),
        ({"speed": 0}, 422, "speed"),
        ({"models": ["no-such-model"]}, 422, "no-such-model"),
        ({"models": ["a", "a"]}, 422, "distinct"),
        ({"bins": {"wheel-a": "bin x"}}, 422, "bins"),
        ({"models": ["wheel-a"], "bins": {"wheel-b": "bin-1"}}, 422, "not in the recipe"),
        ({"models": ["wheel-a"], "bins": {"wheel-a": "bin-9"}}, 422, "no bin named bin-9"),
        ({"extra": 1}, 422, "extra"),
        ({"description": "d" * 2001}, 422, "description"),
    ],
)
def test_bad_bodies_are_refused_and_store_nothing(
    client, headers, settings, body, status, fragment
):
    _model(client, headers, "wheel-a")
    _model(client, headers, "wheel-b")
    r = _recipe(client, headers, **body)
    assert r.status_code == status, r.text
    got = r.json()
    assert set(got) == {"error", "detail"} and fragment in str(got["detail"]), got
    assert _count(settings) == 0


def test_names_and_numbers_are_unique_in_the_cell(client, headers, settings):
    a = _recipe(client, headers).json()
    r = _recipe(client, headers, number=2)
    assert r.status_code == 409 and "named 'wheels'" in r.json()["detail"], r.text
    r = _recipe(client, headers, name="other")
    assert r.status_code == 409 and "numbered 1" in r.json()["detail"], r.text
    b = _recipe(client, headers, name="other", number=2).json()
    r = client.patch(f"/api/recipes/{b['id']}", json={"number": 1}, headers=headers["engineer"])
    assert r.status_code == 409, r.text
    r = client.patch(f"/api/recipes/{a['id']}", json={"number": 1, "name": "wheels"},
                     headers=headers["engineer"])  # fmt: skip
    assert r.status_code == 200, r.text  # its own name and number are free to it
    r = client.patch(f"/api/recipes/{a['id']}", json={"policy": None}, headers=headers["engineer"])
    assert r.status_code == 422 and "may not be null" in r.json()["detail"], r.text
    assert _count(settings) == 2


def test_missing_and_bad_ids(client, headers):
    for path in ("/api/recipes/99", "/api/recipes/99/activate"):
        method = client.post if path.endswith("activate") else client.get
        r = method(path, headers=headers["engineer"])
        assert r.status_code == 404 and r.json()["error"] == "not_found", r.text
    for bad in ("0", "-1", "2147483648", "x"):
        r = client.get(f"/api/recipes/{bad}", headers=headers["viewer"])
        assert r.status_code == 422 and set(r.json()) == {"error", "detail"}, (bad, r.text)


def _recipe_value(**kw) -> recipe_model.Recipe:
    from datetime import UTC, datetime

    t = datetime(2026, 1, 1, tzinfo=UTC)
    base = dict(id=3, name="wheels", number=5, description="", active=True, created_at=t,
                updated_at=t, options=recipe_model.RecipeOptions(policy="top-only", max_views=1,
                                                                 sort=True, threshold=0.3),
                models=("wheel-a",), bins=(("wheel-a", "bin-x"),))  # fmt: skip
    base.update(kw)
    return recipe_model.Recipe(**base)


def test_options_for_takes_the_recipe_under_the_explicit_options():
    r = _recipe_value()
    assert (r.policy, r.max_views, r.sort, r.threshold) == ("top-only", 1, True, 0.3)
    o = recipe_model.options_for(r, {})
    assert (o.policy, o.max_views, o.sort, o.threshold) == ("top-only", 1, True, 0.3)
    assert (o.models, o.bins, o.recipe_id, o.recipe_name) == (
        ("wheel-a",), (("wheel-a", "bin-x"),), 3, "wheels")  # fmt: skip
    assert o.bin_of("wheel-a") == "bin-x" and o.bin_of("wheel-b") is None
    o = recipe_model.options_for(r, {"policy": "naive", "sort": False, "wait_s": 5.0})
    assert (o.policy, o.sort, o.wait_s, o.max_views, o.recipe_name) == (
        "naive",
        False,
        5.0,
        1,
        "wheels",
    )
    assert recipe_model.options_for(None, {"sort": True}) == InspectOptions(sort=True)
    with pytest.raises(InvalidInput, match="unknown options"):
        recipe_model.options_for(r, {"recipe_name": "forged"})
    with pytest.raises(InvalidInput, match="max_views"):
        recipe_model.options_for(r, {"max_views": 9})


def test_plc_interface_selects_by_number_and_is_audited(client, headers, settings):
    """``activate_number`` / ``activate`` / ``active_recipe`` as a PLC link calls them, on
    the cell's own database."""
    a = _recipe(client, headers).json()
    b = _recipe(client, headers, name="steel", number=42, belt_mode="index").json()

    async def run() -> tuple:
        db = Database(settings.database_url)
        try:
            async with db.session() as s:
                cell_id = await s.scalar(select(RecipeRow.cell_id).where(RecipeRow.id == a["id"]))
            rt = SimpleNamespace(database=db, cell_id=cell_id, sim=None)
            before = await service.active_recipe(rt)
            got = await service.activate_number(rt, 42, actor="opcua:line-plc", role="plc")
            now = await service.active_recipe(rt)
            listed = await service.list_recipes(rt)
            errors = []
            for call in (lambda: service.activate_number(rt, 43, actor="plc"),
                         lambda: service.activate(rt, 10_000, actor="plc"),
                         lambda: service.activate(rt, 0, actor="plc"),
                         lambda: service.activate_number(rt, 0, actor="plc")):  # fmt: skip
                try:
                    await call()
                except (NotFound, InvalidInput) as exc:
                    errors.append(type(exc).__name__)
            again = await service.activate(rt, a["id"], actor="modbus")
            return before, got, now, listed, errors, again
        finally:
            await db.dispose()

    before, got, now, listed, errors, again = asyncio.run(run())
    assert before is None
    assert got.id == b["id"] and got.active and got.belt_mode == "index"
    assert now == got
    assert [r.number for r in listed] == [1, 42] and [r.active for r in listed] == [False, True]
    assert errors == ["NotFound", "NotFound", "InvalidInput", "InvalidInput"]
    assert again.id == a["id"]
    trail = client.get("/api/audit?kind=recipe&action=activate", headers=headers["engineer"]).json()
    acts = [(e["actor"], e["actor_role"], e["entity_id"]) for e in reversed(trail["data"])
            if e["action"] == "activate"]  # fmt: skip
    assert acts == [("opcua:line-plc", "plc", str(b["id"])), ("modbus", "system", str(a["id"]))]


def test_concurrent_first_selections_leave_one_active_recipe(client, headers, settings):
    """Several links selecting at once on a cell with no active recipe yet: every call ends
    in a selection (never an integrity error), and the cell has one active recipe."""
    ids = [_recipe(client, headers, name=f"r{k}", number=k + 1).json()["id"] for k in range(4)]

    async def run() -> tuple[list[object], int, int]:
        db = Database(settings.database_url)
        try:
            async with db.session() as s:
                cell_id = await s.scalar(select(RecipeRow.cell_id).where(RecipeRow.id == ids[0]))
            rt = SimpleNamespace(database=db, cell_id=cell_id, sim=None)
            got = await asyncio.gather(
                *(service.activate(rt, i, actor=f"plc-{i}") for i in ids), return_exceptions=True
            )
            active = await service.active_recipe(rt)
            async with db.session() as s:
                n = await s.scalar(text("SELECT count(*) FROM recipe_selections"))
            return got, active.id, int(n)
        finally:
            await db.dispose()

    got, active, n = asyncio.run(run())
    assert [getattr(g, "id", g) for g in got] == ids
    assert n == 1 and active in ids
