"""``visioncell inspect once | run``: inspections by the running cell (its arm and camera).

Both ask the running cell (``--url``, ``--token`` of an operator) through the REST API and
follow the job: ``once`` inspects the object at the station and prints the decision, the
model, the score, the viewpoints and the pose; ``run`` starts continuous operation
(``--count`` objects, or until Ctrl-C, which asks the cell to stop after the current one).
"""

from __future__ import annotations

import math
import time
from typing import Annotated, Any

import typer

from backend.cli.models import _fail, _request, _settings

__all__ = ["inspect_app", "register"]

inspect_app = typer.Typer(help="Inspect objects at the station.", no_args_is_help=True)
POLICIES = ("naive", "top-only", "two-views", "best-next")


def register(app: typer.Typer) -> None:
    """Add the ``inspect`` command group to the ``visioncell`` app."""
    app.add_typer(inspect_app, name="inspect")


def _base(url: str | None) -> str:
    if url is None:
        s = _settings()
        url = f"http://{s.http_host}:{s.http_port}"
    return url.rstrip("/") + "/api"


def _body(policy: str, sort: bool, wait: float) -> dict[str, Any]:
    if policy not in POLICIES:
        raise _fail(f"--policy must be one of {', '.join(POLICIES)}, got {policy!r}")
    if not (math.isfinite(wait) and 0.0 <= wait <= 600.0):
        raise _fail(f"--wait must be in [0, 600] s, got {wait!r}")
    return {"policy": policy, "sort": sort, "wait_s": wait}


def _line(row: dict[str, Any]) -> str:
    pose = row.get("pose") or {}
    where = ""
    if pose:
        x, y, z = pose["position_m"]
        where = f" at ({x * 1e3:.1f}, {y * 1e3:.1f}, {z * 1e3:.1f}) mm yaw {math.degrees(pose['yaw_rad']):.1f} deg"
    score = "" if row["score"] is None else f" score {row['score']:.2f}"
    vps = ",".join(str(v) for v in row["viewpoints_visited"])
    return f"#{row['id']} {row['decision']} {row['model'] or '-'}{score} views [{vps}]{where}: {row['reason']}"


def _follow(base: str, token: str, job: dict[str, Any]) -> dict[str, Any]:
    last = ""
    while job["state"] == "running":
        if job["message"] != last:
            last = job["message"]
            print(f"{100 * job['progress']:5.1f} %  {last}", flush=True)
        time.sleep(0.5)
        job = _request(f"{base}/jobs/{job['id']}", token)
    return job


@inspect_app.command("once")
def once(
    token: Annotated[str, typer.Option(help="Operator token", envvar="VISIONCELL_TOKEN")],
    url: Annotated[str | None, typer.Option(help="Cell URL (default: from the settings)")] = None,
    policy: Annotated[str, typer.Option(help=", ".join(POLICIES))] = "two-views",
    sort: Annotated[bool, typer.Option(help="Pick and sort into the part's bin")] = False,
    wait: Annotated[float, typer.Option(help="Longest wait for the object, s")] = 60.0,
) -> None:
    """Inspect the object at the station and print the stored result."""
    base = _base(url)
    job = _request(f"{base}/inspections", token, "POST", _body(policy, sort, wait))["job"]
    job = _follow(base, token, job)
    if job["state"] != "done":
        err = job.get("error") or {}
        raise _fail(f"the inspection {job['state']}: {err.get('detail', job['message'])}")
    print(_line(job["result"]["inspection"]))


@inspect_app.command("run")
def run(
    token: Annotated[str, typer.Option(help="Operator token", envvar="VISIONCELL_TOKEN")],
    url: Annotated[str | None, typer.Option(help="Cell URL (default: from the settings)")] = None,
    policy: Annotated[str, typer.Option(help=", ".join(POLICIES))] = "two-views",
    sort: Annotated[bool, typer.Option(help="Pick and sort into the part's bin")] = False,
    count: Annotated[
        int | None, typer.Option(help="Objects to inspect (default: until Ctrl-C)")
    ] = None,
    wait: Annotated[float, typer.Option(help="Longest wait for each object, s")] = 60.0,
) -> None:
    """Continuous operation; prints each inspection as it is stored."""
    if count is not None and not 1 <= count <= 10_000:
        raise _fail(f"--count must be in 1..10000, got {count!r}")
    base = _base(url)
    body = {**_body(policy, sort, wait), "count": count}
    job = _request(f"{base}/inspection/run", token, "POST", body)["job"]
    seen: set[int] = set()
    try:
        while True:
            job = _request(f"{base}/jobs/{job['id']}", token)
            page = _request(f"{base}/inspections?limit=20", token)
            for row in sorted(page["data"], key=lambda r: r["id"]):
                if row["id"] not in seen and row["started_at"] >= job["created_at"][:26]:
                    seen.add(row["id"])
                    print(_line(row), flush=True)
            if job["state"] != "running":
                break
            time.sleep(0.5)
    except KeyboardInterrupt:
        _request(f"{base}/inspection/stop", token, "POST", {})
        print("stopping after the current object", flush=True)
        job = _follow(base, token, job)
    if job["state"] != "done":
        err = job.get("error") or {}
        raise _fail(f"the run {job['state']}: {err.get('detail', job['message'])}")
    print(f"inspected {job['result']['inspected']}: {job['result']['decisions']}")
