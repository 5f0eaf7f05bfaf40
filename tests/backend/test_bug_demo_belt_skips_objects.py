"""Bug (the operator's path): a continuous run on the demo belt (six objects 0.42 m apart,
index mode) stored every other row ``failed no_object: the previous object did not leave the
station within 60 s``, its complete rows named one object, and five of six were never
inspected: the top view sees more belt than the spacing, so the empty station the run waited
for between two objects never came.

Now the run holds each part at the station until it is inspected, then lets the belt bring
the next, and tells a new part from the one inspected by where it rides on the belt: every
object of the demo belt is inspected once, in the belt's order.  The test reads the
simulator's truth stored with each row to check; the run itself never does."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from robot.sim.demo import DEMO_OBJECTS
from tests.utils.cli import cli_token, teach_at_station, wait_job
from tests.utils.factories import free_port, make_settings, migrate

pytestmark = pytest.mark.slow


def test_a_run_of_the_demo_belt_inspects_every_object_once_in_order(tmp_path):
    settings = make_settings(tmp_path, driver="sim", camera="sim", sim_demo=False, time_scale=5.0)
    migrate(settings)
    eng = {"Authorization": f"Bearer {cli_token(settings, 'eve', 'engineer')}"}
    op = {"Authorization": f"Bearer {cli_token(settings, 'otto', 'operator')}"}
    with TestClient(create_app(settings)) as client:  # a model taught, as a new user does
        teach_at_station(client, eng, "wheel-5spoke", part="wheel")

    # Restarted with the demo belt: six objects 0.42 m apart, indexing at the station.
    demo = settings.model_copy(
        update={"sim_demo": True, "http_port": free_port(), "viser_port": free_port()}
    )
    with TestClient(create_app(demo)) as client:
        r = client.post("/api/inspection/run", json={"count": 6, "policy": "top-only",
                                                     "max_views": 1}, headers=op)  # fmt: skip
        assert r.status_code == 202, r.text
        job = wait_job(client, op, r.json()["job"]["id"], timeout_s=1200)
        assert job["state"] == "done", job
        assert job["result"]["inspected"] == 6, job["result"]
        rows = sorted(client.get("/api/inspections?limit=20", headers=op).json()["data"],
                      key=lambda d: d["id"])  # fmt: skip
    assert len(rows) == 6
    seen = [(r["decision"], (r["truth"] or {}).get("name"), r["reason"][:70]) for r in rows]
    assert all(r["decision"] != "failed" for r in rows), seen
    ids = [r["truth"]["id"] for r in rows]
    assert len(set(ids)) == 6, seen  # each object once
    names = [r["truth"]["name"] for r in rows]
    k = DEMO_OBJECTS.index(names[0])  # in the belt's order, from the one at the station
    assert names == [DEMO_OBJECTS[(k + i) % 6] for i in range(6)], seen
    wheel = [r for r in rows if r["truth"]["name"] == "wheel-5spoke"]
    assert wheel[0]["decision"] == "recognized" and wheel[0]["model"] == "wheel-5spoke", seen
