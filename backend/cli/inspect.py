"""``visioncell inspect once | run``: inspections by the running cell (its arm and camera).

Both ask the running cell (``--url``, ``--token`` of an operator) through the REST API and
follow the job: ``once`` inspects the object at the station and prints the decision, the
model, the score, the viewpoints, the pose, what became of the part (its bin) and how long
it took; ``run`` starts continuous operation
(``--count`` objects, or until Ctrl-C, which asks the cell to stop after the current one).
Both take the cell's active recipe (``--recipe ID``: another one); ``--policy`` and
``--sort/--no-sort`` given override it.
"""

from __future__ import annotations

import math
import time
import urllib.parse
from typing import Annotated, Any

import typer

from backend.cli.remote import POLL_S, cell_api, follow_job, job_failure, job_of, read_job, request
from backend.cli.remote import fail as _fail

__all__ = ["inspect_app", "register"]

inspect_app = typer.Typer(help="Inspect objects at the station.", no_args_is_help=True)
POLICIES = ("naive", "top-only", "two-views", "best-next")


def register(app: typer.Typer) -> None:
    """Add the ``inspect`` command group to the ``visioncell`` app."""
    app.add_typer(inspect_app, name="inspect")


def _body(policy: str | None, sort: bool | None, wait: float,
          recipe: int | None = None) -> dict[str, Any]:  # fmt: skip
    """The request: the options given (the recipe's hold for the others)."""
    if policy is not None and policy not in POLICIES:
        raise _fail(f"--policy must be one of {', '.join(POLICIES)}, got {policy!r}")
    if not (math.isfinite(wait) and 0.0 <= wait <= 600.0):
        raise _fail(f"--wait must be in [0, 600] s, got {wait!r}")
    if recipe is not None and not 1 <= recipe <= 2**31 - 1:
        raise _fail(f"--recipe must be a recipe id (1..{2**31 - 1}), got {recipe!r}")
    body: dict[str, Any] = {"wait_s": wait}
    for key, value in (("policy", policy), ("sort", sort), ("recipe", recipe)):
        if value is not None:
            body[key] = value
    return body


def _line(row: dict[str, Any]) -> str:
    pose = row.get("pose") or {}
    where = ""
    if pose:
        x, y, z = pose["position_m"]
        where = f" at ({x * 1e3:.1f}, {y * 1e3:.1f}, {z * 1e3:.1f}) mm yaw {math.degrees(pose['yaw_rad']):.1f} deg"
    score = "" if row["score"] is None else f" score {row['score']:.2f}"
    vps = ",".join(str(v) for v in row["viewpoints_visited"])
    recipe = f" recipe {row['recipe']}" if row.get("recipe") else ""
    # What became of the part (the bin it went to) and how long the inspection took, as the
    # console, the reports and the CSV show them.
    pick = (row.get("pick_outcome") or {}).get("text") or "not sorted"
    took = "" if row.get("duration_s") is None else f"; {row['duration_s']:.2f} s"
    return (f"#{row['id']} {row['decision']} {row['model'] or '-'}{score} views [{vps}]{where}"
            f"{recipe}: {row['reason']}; {pick}{took}")  # fmt: skip


#: The options both commands take (the recipe's values unless given).
TokenOpt = Annotated[str, typer.Option(help="Operator token", envvar="VISIONCELL_TOKEN")]
UrlOpt = Annotated[str | None, typer.Option(help="Cell URL (default: from the settings)")]
PolicyOpt = Annotated[
    str | None, typer.Option(help=", ".join(POLICIES) + " (default: the recipe's)")
]
SortOpt = Annotated[
    bool | None, typer.Option(help="Pick and sort into the part's bin (default: the recipe's)")
]
RecipeOpt = Annotated[
    int | None, typer.Option(help="Recipe id to use (default: the active recipe)")
]


@inspect_app.command("once")
def once(
    token: TokenOpt,
    url: UrlOpt = None,
    policy: PolicyOpt = None,
    sort: SortOpt = None,
    recipe: RecipeOpt = None,
    wait: Annotated[float, typer.Option(help="Longest wait for the object, s")] = 60.0,
) -> None:
    """Inspect the object at the station and print the stored result."""
    base = cell_api(url)
    job = job_of(request(f"{base}/inspections", token, "POST", _body(policy, sort, wait, recipe)))
    job = follow_job(base, token, job)
    if job["state"] != "done":
        raise job_failure(job, "inspection")
    print(_line(job["result"]["inspection"]))


@inspect_app.command("run")
def run(
    token: TokenOpt,
    url: UrlOpt = None,
    policy: PolicyOpt = None,
    sort: SortOpt = None,
    recipe: RecipeOpt = None,
    count: Annotated[
        int | None, typer.Option(help="Objects to inspect (default: until Ctrl-C)")
    ] = None,
    wait: Annotated[float, typer.Option(help="Longest wait for each object, s")] = 60.0,
) -> None:
    """Continuous operation; prints each inspection as it is stored."""
    if count is not None and not 1 <= count <= 10_000:
        raise _fail(f"--count must be in 1..10000, got {count!r}")
    base = cell_api(url)
    body = {**_body(policy, sort, wait, recipe), "count": count}
    job = job_of(request(f"{base}/inspection/run", token, "POST", body))
    # The run's own inspections: those started since the job was created, each printed once.
    since = urllib.parse.urlencode({"since": job["created_at"], "limit": 50})
    seen: set[int] = set()

    def show_new() -> None:
        page = request(f"{base}/inspections?{since}", token)
        for row in sorted(page["data"], key=lambda r: r["id"]):
            if row["id"] not in seen:
                seen.add(row["id"])
                print(_line(row), flush=True)

    try:
        while True:
            job = read_job(base, token, job["id"])
            show_new()
            if job["state"] != "running":
                break
            time.sleep(POLL_S)
    except KeyboardInterrupt:
        request(f"{base}/inspection/stop", token, "POST", {})
        print("stopping after the current object", flush=True)
        job = follow_job(base, token, job)
        show_new()
    if job["state"] != "done":
        raise job_failure(job, "run")
    result = job["result"] or {}
    decisions = result.get("decisions") or {}
    counts = ", ".join(f"{d} {n}" for d, n in sorted(decisions.items())) or "nothing"
    print(f"inspected {result.get('inspected', len(seen))}: {counts}")
