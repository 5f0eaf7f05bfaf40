"""A plant of two cells (issue 16 part 4): two ``visioncell serve`` processes with different
cell names on one PostgreSQL database, each with its simulated cell.

A model taught on cell A is used by cell B without a restart (B's live index hears of it
through LISTEN/NOTIFY); B's model reaches A the same way; calibrations and inspections stay
per cell; with both processes busy at once (A teaching and uploading views, B inspecting)
no row is lost and nothing deadlocks (every request and job ends within its bound)."""

from __future__ import annotations

import concurrent.futures
import time

import httpx
import pytest

from robot.sim.world import ConveyorSpec
from tests.e2e.conftest import Server, start_server
from tests.utils.factories import make_settings, make_tokens
from tests.utils.models import png_bytes, textured_rgb
from tests.utils.postgres import postgres_url  # noqa: F401  (the fixture)

# Two simulated cells teach and inspect: about two minutes on an idle 2-core machine, far
# more when it is shared; every wait below is bounded on its own.
pytestmark = [pytest.mark.e2e, pytest.mark.slow, pytest.mark.timeout(1800)]

STATION = ConveyorSpec().station_s_m
TIMEOUT = 30.0  # one request
JOB_S = 600.0  # one job on a loaded machine (a bound, not a timing assertion)


def _start(tmp_path, url: str, name: str) -> Server:
    return start_server(
        tmp_path / name,
        ready_s=300.0,  # two simulated cells starting on a loaded machine
        VISIONCELL_DATABASE_URL=url,
        VISIONCELL_CELL_NAME=name,
        VISIONCELL_DRIVER="sim",
        VISIONCELL_CAMERA="sim",
        VISIONCELL_SIM_DEMO="false",
        VISIONCELL_TIME_SCALE="2",
        VISIONCELL_CAMERA_FPS="4",
        VISIONCELL_VIEW3D_ENABLED="false",
    )


def _wait_job(s: Server, hdr, job_id: str, *, until: str | None = None) -> dict:
    t0 = time.monotonic()
    while time.monotonic() - t0 < JOB_S:
        job = httpx.get(f"{s.base}/api/jobs/{job_id}", headers=hdr, timeout=TIMEOUT).json()["job"]
        if job["state"] != "running" or (until is not None and until in job["message"]):
            return job
        time.sleep(0.3)
    raise AssertionError(f"job {job_id} still running after {JOB_S} s: {job['message']}")


def _eventually(check, what: str, timeout_s: float = 30.0) -> None:
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout_s:
        if check():
            return
        time.sleep(0.2)
    raise AssertionError(f"not within {timeout_s} s: {what}")


def _spawn(s: Server, hdr, name: str, yaw: float = 0.0) -> None:
    _clear(s, hdr)
    c = httpx.Client(base_url=s.base, headers=hdr, timeout=TIMEOUT)
    r = c.post("/api/sim/objects", json={"name": name, "position_along_belt_m": STATION,
                                         "yaw_rad": yaw})  # fmt: skip
    assert r.status_code == 201, r.text


def _clear(s: Server, hdr) -> None:
    for obj in httpx.get(f"{s.base}/api/sim/objects", headers=hdr, timeout=TIMEOUT).json()["data"]:
        httpx.delete(f"{s.base}/api/sim/objects/{obj['id']}", headers=hdr, timeout=TIMEOUT)


def _teach(s: Server, hdr, name: str) -> int:
    """Create a 2d model of catalogue object ``name`` and teach it with the arm."""
    r = httpx.post(f"{s.base}/api/models", json={"name": name, "kind": "2d"}, headers=hdr,
                   timeout=TIMEOUT)  # fmt: skip
    assert r.status_code == 201, r.text
    mid = r.json()["id"]
    httpx.post(f"{s.base}/api/sim/conveyor", json={"running": False, "mode": "index"},
               headers=hdr, timeout=TIMEOUT)  # fmt: skip
    _clear(s, hdr)
    r = httpx.post(f"{s.base}/api/models/{mid}/teach", json={"background": "grab", "wait_s": 120},
                   headers=hdr, timeout=TIMEOUT)  # fmt: skip
    assert r.status_code == 202, r.text
    job = _wait_job(s, hdr, r.json()["job"]["id"], until="waiting for an object")
    _spawn(s, hdr, name)
    job = _wait_job(s, hdr, job["id"])
    assert job["state"] == "done", job
    _clear(s, hdr)
    return mid


def _indexed(s: Server, hdr, mid: int) -> int:
    r = httpx.get(f"{s.base}/api/models/{mid}", headers=hdr, timeout=TIMEOUT)
    return int(r.json()["indexed_views"]) if r.status_code == 200 else -1


def _inspect(s: Server, hdr, name: str, yaw: float) -> dict:
    _spawn(s, hdr, name, yaw)
    r = httpx.post(f"{s.base}/api/inspections", json={"policy": "top-only", "wait_s": 30},
                   headers=hdr, timeout=TIMEOUT)  # fmt: skip
    assert r.status_code == 202, r.text
    job = _wait_job(s, hdr, r.json()["job"]["id"])
    assert job["state"] == "done", job
    return job["result"]["inspection"]


def test_two_cells_share_models_keep_their_inspections_and_run_busy_at_once(
    tmp_path,
    postgres_url,  # noqa: F811
):
    with concurrent.futures.ThreadPoolExecutor(max_workers=2) as pool:
        starting = [pool.submit(_start, tmp_path, postgres_url, n) for n in ("cell-a", "cell-b")]
        concurrent.futures.wait(starting)
    servers = [f.result() for f in starting if f.exception() is None]
    if len(servers) < 2:
        for s in servers:
            s.stop()
        raise next(f.exception() for f in starting if f.exception() is not None)
    a, b = servers
    try:
        # Users belong to the plant: one engineer token for both cells.
        token = make_tokens(make_settings(tmp_path / "users", database_url=postgres_url))
        hdr = {"Authorization": f"Bearer {token['engineer']}"}
        cells = httpx.get(f"{b.base}/api/cells", headers=hdr, timeout=TIMEOUT).json()["data"]
        assert {c["name"] for c in cells} == {"cell-a", "cell-b"}

        # Taught on A, indexed by B without a restart.
        gear = _teach(a, hdr, "gear-housing")
        n_gear = _indexed(a, hdr, gear)
        assert n_gear >= 1
        _eventually(lambda: _indexed(b, hdr, gear) == n_gear, "A's views in B's index")
        # B teaches its own model (and grabs its own empty-belt background): A learns of it.
        wheel = _teach(b, hdr, "wheel-steel")
        n_wheel = _indexed(b, hdr, wheel)
        _eventually(lambda: _indexed(a, hdr, wheel) == n_wheel, "B's views in A's index")

        # B recognises the object with the model taught on A (near the taught yaw: at any
        # yaw recognition is issue 14's open miss, not the plant's).
        row = _inspect(b, hdr, "gear-housing", 0.02)
        assert row["decision"] == "recognized" and row["model"] == "gear-housing", row
        # A inspects too, with B's model.
        row_a = _inspect(a, hdr, "wheel-steel", 0.0)
        assert row_a["decision"] == "recognized" and row_a["model"] == "wheel-steel", row_a

        # Both busy at once: B inspects while A uploads views (engineer) of a new model.
        r = httpx.post(f"{a.base}/api/models", json={"name": "uploaded", "kind": "2d"},
                       headers=hdr, timeout=TIMEOUT)  # fmt: skip
        up = r.json()["id"]

        def upload(k: int) -> list[int]:
            files = [("images", (f"v{k}.png", png_bytes(textured_rgb(100 + k)), "image/png"))]
            r = httpx.post(f"{a.base}/api/models/{up}/views", files=files,
                           data={"viewpoints": "1"}, headers=hdr, timeout=TIMEOUT)  # fmt: skip
            assert r.status_code == 201, r.text
            return [v["id"] for v in r.json()["data"]]

        uploads = 6
        with concurrent.futures.ThreadPoolExecutor(max_workers=3) as pool:
            futures = [pool.submit(upload, k) for k in range(uploads)]
            inspected = [_inspect(b, hdr, "wheel-steel", 0.01 * k) for k in range(3)]
            view_ids = sorted(v for f in futures for v in f.result(timeout=JOB_S))
        assert len(view_ids) == uploads
        assert all(r["decision"] == "recognized" for r in inspected), inspected
        _eventually(lambda: _indexed(b, hdr, up) == uploads, "the uploads in B's index")
        listed = httpx.get(f"{b.base}/api/models/{up}/views", headers=hdr, timeout=TIMEOUT)
        assert sorted(v["id"] for v in listed.json()["data"]) == view_ids

        # Inspections stay per cell: B has its four, A its one; neither sees the other's.
        ins_b = httpx.get(f"{b.base}/api/inspections", headers=hdr, timeout=TIMEOUT).json()
        ins_a = httpx.get(f"{a.base}/api/inspections", headers=hdr, timeout=TIMEOUT).json()
        assert ins_b["count"] == 4 and ins_a["count"] == 1
        assert sorted(d["id"] for d in ins_b["data"]) == sorted(
            [row["id"]] + [r["id"] for r in inspected]
        )
        assert [d["id"] for d in ins_a["data"]] == [row_a["id"]]
        gone = httpx.get(f"{a.base}/api/inspections/{row['id']}", headers=hdr, timeout=TIMEOUT)
        assert gone.status_code == 404
        gone = httpx.get(f"{b.base}/api/inspections/{row_a['id']}", headers=hdr, timeout=TIMEOUT)
        assert gone.status_code == 404
        # Reports span both cells or filter one (the /api/reports routes of issue 16's
        # reports work; checked once they are merged, 404 before).
        rep = httpx.get(f"{a.base}/api/reports/summary", headers=hdr, timeout=TIMEOUT)
        if rep.status_code != 404:
            assert rep.status_code == 200 and rep.json()["count"] == 5, rep.text
            for name, n in (("cell-a", 1), ("cell-b", 4)):
                r = httpx.get(f"{b.base}/api/reports/summary", params={"cell": name},
                              headers=hdr, timeout=TIMEOUT)  # fmt: skip
                assert r.status_code == 200 and r.json()["count"] == n, (name, r.text)
        # A deletion on B reaches A's index too.
        assert (
            httpx.delete(f"{b.base}/api/models/{up}", headers=hdr, timeout=TIMEOUT).status_code
            == 204
        )
        _eventually(lambda: _indexed(a, hdr, up) == -1 and _indexed(a, hdr, gear) == n_gear,
                    "the deletion in A")  # fmt: skip
    finally:
        b.stop()
        a.stop()
