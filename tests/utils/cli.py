"""What a user has: a token printed by ``visioncell user add``, jobs followed through REST,
a model taught in the wizard's steps."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from typing import Any

from backend.settings import Settings


def cli_token(settings: Settings, name: str, role: str) -> str:
    """A new user's token, printed by ``visioncell user add NAME --role ROLE`` (a real
    process on the database and secret of ``settings``)."""
    env = {
        **os.environ,
        "VISIONCELL_DATABASE_URL": settings.database_url,
        "VISIONCELL_SECRET_KEY": settings.secret_key.get_secret_value(),
        "VISIONCELL_VAR_DIR": str(settings.var_dir),
    }
    r = subprocess.run(
        [sys.executable, "-m", "backend.cli", "user", "add", name, "--role", role],
        capture_output=True, text=True, env=env, timeout=120, check=True,
    )  # fmt: skip
    return r.stdout.strip().splitlines()[-1]


def wait_job(client: Any, headers: dict[str, str], job_id: int, *, until: str | None = None,
             timeout_s: float = 300.0) -> dict[str, Any]:  # fmt: skip
    """``GET /api/jobs/{id}`` until the job ended, or its message holds ``until``; the
    timeout only bounds a hang."""
    t0 = time.monotonic()
    job: dict[str, Any] = {}
    while time.monotonic() - t0 < timeout_s:
        job = client.get(f"/api/jobs/{job_id}", headers=headers).json()["job"]
        if job["state"] != "running" or (until is not None and until in (job["message"] or "")):
            return job
        time.sleep(0.2)
    raise AssertionError(f"job {job_id} still running after {timeout_s} s: {job.get('message')}")


def teach_at_station(client: Any, eng: dict[str, str], name: str, *, kind: str = "2d",
                     part: str | None = None) -> int:  # fmt: skip
    """Create model ``name`` and teach it as the console's wizard does on the simulator
    (clear the station, grab the empty belt, place the catalogue part ``name`` at the
    station, one roll), then clear the station again; returns the model's id."""
    body: dict[str, Any] = {"name": name, "kind": kind, **({"part": part} if part else {})}
    r = client.post("/api/models", json=body, headers=eng)
    assert r.status_code == 201, r.text
    model_id = int(r.json()["id"])
    clear_station(client, eng)
    r = client.post(f"/api/models/{model_id}/teach",
                    json={"background": "grab", "wait_s": 120, "top_rolls_rad": [0.0]},
                    headers=eng)  # fmt: skip
    assert r.status_code == 202, r.text
    job = wait_job(client, eng, r.json()["job"]["id"], until="waiting for an object")
    # the belt is stopped: a part placed without a position goes to the station
    r = client.post("/api/sim/objects", json={"name": name, "yaw_rad": 0.0}, headers=eng)
    assert r.status_code == 201, r.text
    job = wait_job(client, eng, job["id"])
    assert job["state"] == "done", job
    clear_station(client, eng)
    return model_id


def clear_station(client: Any, eng: dict[str, str]) -> None:
    """The wizard's "clear the station": the belt stopped (index mode, held) and empty."""
    r = client.post("/api/sim/conveyor", json={"running": False, "mode": "index", "dwell_s": None},
                    headers=eng)  # fmt: skip
    assert r.status_code == 200, r.text
    for o in client.get("/api/sim/objects?limit=100", headers=eng).json()["data"]:
        assert client.delete(f"/api/sim/objects/{o['id']}", headers=eng).status_code == 204


def wait_station_seen_empty(client: Any, headers: dict[str, str], run_id: int, *, done: int,
                            count: int, timeout_s: float = 600.0) -> dict[str, Any]:  # fmt: skip
    """Wait until the continuous run ``run_id`` (of ``count`` objects) has inspected ``done``
    of them and then looked at the station and found no part there (its job says "waiting
    for a part at the station" at that progress; the part just inspected is "the next part"),
    or has ended.  What a fixed pause before the next object used to hope for; the timeout
    only bounds a hang."""
    t0 = time.monotonic()
    job: dict[str, Any] = {}
    while time.monotonic() - t0 < timeout_s:
        job = client.get(f"/api/jobs/{run_id}", headers=headers).json()["job"]
        if job["state"] != "running":
            return job
        if job["progress"] >= done / count - 1e-9 and (job["message"] or "").startswith(
            "waiting for a part at the station"
        ):
            return job
        time.sleep(0.1)
    raise AssertionError(
        f"run {run_id} did not see the station empty after {done} inspection(s) within "
        f"{timeout_s} s: {job.get('message')}"
    )
