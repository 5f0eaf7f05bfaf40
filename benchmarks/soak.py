"""Soak: many inspections in the simulator with resources sampled (issue 16, part 5).

One simulated cell (accelerated time) runs continuous inspection
(:func:`backend.inspection.service.start_run`) on objects the feeder of
:mod:`benchmarks.faults` puts at the station one at a time (every ``--taught-every``-th the
taught model, recognised with its pose and an approach move; the others an untrained part,
``unknown``).  After every inspection the process's resident memory (``VmRSS``), its open
file descriptors (``/proc/self/fd``) and the database connections (the pool's checked-out
and pooled connections) are sampled.  After the warm-up (``--warmup`` inspections) a line
is fitted (least squares) to each series against the inspection count; the slope is quoted
per 1,000 inspections next to the bound it must stay under.  Baseline in the same run: the
same cell idle (no inspections) for ``--idle-s`` seconds, sampled the same way.

Run::

    nice -n 5 .venv/bin/python -m benchmarks.soak [--inspections 1000] [--json]

Plot: ``benchmarks/out/soak.png`` (``--docs``: ``docs/soak.png``).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console
from rich.table import Table

os.environ.setdefault("MUJOCO_GL", "egl")

out = Console()
err = Console(stderr=True)

OUT_DIR = Path(__file__).parent / "out"
DOCS_DIR = Path(__file__).parent.parent / "docs"
#: Bounds per 1,000 inspections after the warm-up: RSS MB, open files, DB connections.
BOUNDS = {"rss_mb": 20.0, "open_files": 1.0, "db_connections": 1.0}
#: Series reported beside them (not plotted): open files other than the database's own.
EXTRA_BOUNDS = {"other_files": 1.0}
WINDOW = 5
"""Samples in the early and late medians."""


def rss_mb() -> float:
    """Resident memory of this process, MB (``/proc/self/status`` VmRSS)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    raise RuntimeError("no VmRSS in /proc/self/status")


def open_files() -> int:
    """Open file descriptors of this process."""
    return len(os.listdir("/proc/self/fd"))


def other_files(db: Any) -> int:
    """Open file descriptors that are not the SQLite database's own files (the file, its
    WAL, shared memory and journal): those come and go with the pool's connections, which
    :func:`db_connections` counts."""
    path = (
        getattr(db.engine.url, "database", None)
        if db.engine.url.get_backend_name() == "sqlite"
        else None
    )
    base = None if not path else os.path.realpath(path)
    n = 0
    for fd in os.listdir("/proc/self/fd"):
        try:
            target = os.readlink(f"/proc/self/fd/{fd}")
        except OSError:
            continue  # closed since the listing
        if base is None or not target.startswith(base):
            n += 1
    return n


def db_connections(db: Any) -> int:
    """Connections the database pool holds (checked out plus idle in the pool)."""
    pool = db.engine.sync_engine.pool
    held = 0
    for attr in ("checkedout", "checkedin"):
        fn = getattr(pool, attr, None)
        if callable(fn):
            held += int(fn())
    return held


def sample(db: Any) -> dict[str, float]:
    return {"rss_mb": rss_mb(), "open_files": float(open_files()),
            "db_connections": float(db_connections(db)), "other_files": float(other_files(db))}  # fmt: skip


def slope_per_1000(x: list[float], y: list[float]) -> float:
    """Least-squares slope of ``y`` against ``x``, times 1,000 (0 for fewer than 3 points)."""
    if len(x) < 3 or np.ptp(x) == 0:
        return 0.0
    return float(np.polyfit(np.asarray(x), np.asarray(y), 1)[0] * 1000.0)


async def soak(args: argparse.Namespace, progress: Any) -> dict[str, Any]:
    from backend.cell.events import InspectionDone
    from backend.db.migrate import upgrade
    from backend.inspection import service
    from backend.runtime import CellRuntime
    from benchmarks.faults import (
        TAUGHT,
        Feeder,
        settings_for,
        teach_one,
        untrained_name,
        watch_truths,
    )

    tmp = Path(tempfile.mkdtemp(prefix="vc-soak-"))
    url = f"sqlite+aiosqlite:///{tmp / 'soak.db'}"
    await asyncio.to_thread(upgrade, url)
    settings = settings_for(tmp, url, time_scale=args.time_scale, busy_s=30.0, motion_log=None)
    samples: list[dict[str, float]] = []
    idle: list[dict[str, float]] = []
    async with CellRuntime(settings, view3d=False) as rt:
        progress("teaching one model")
        await teach_one(rt, TAUGHT)
        names = tuple([TAUGHT] + [untrained_name()] * (args.taught_every - 1))
        # baseline: the same cell idle
        t_idle = time.monotonic()
        while time.monotonic() - t_idle < args.idle_s:
            idle.append({"t": time.monotonic() - t_idle, **sample(rt.database)})
            await asyncio.sleep(0.5)
        feeder = Feeder(rt, names)
        unwatch = watch_truths(rt, feeder)
        done_at: list[float] = []

        def on_done(ev: Any) -> None:
            s = sample(rt.database)
            s["n"] = float(len(samples) + 1)
            s["decision"] = ev.decision  # type: ignore[assignment]
            samples.append(s)
            done_at.append(time.monotonic())
            if len(samples) % max(1, args.inspections // 20) == 0:
                progress(f"{len(samples)}/{args.inspections} inspections, "
                         f"RSS {s['rss_mb']:.1f} MB, {int(s['open_files'])} files")  # fmt: skip

        rt.bus.add_listener(on_done, InspectionDone)
        feeder.start()
        task = asyncio.create_task(feeder.run())
        opts = service.InspectOptions(policy=args.policy, max_views=2, wait_s=30.0)
        t0 = time.monotonic()
        run = service.start_run(rt, opts, args.inspections)

        async def budget() -> None:  # a wall-time budget ends the run after its object
            await asyncio.sleep(args.max_wall_s)
            progress(f"wall-time budget of {args.max_wall_s:g} s spent: stopping the run")
            service.stop_run(rt)

        guard = asyncio.create_task(budget())
        await rt.jobs.wait(run.job)
        guard.cancel()
        unwatch()
        if task.done() and not task.cancelled() and task.exception() is not None:
            raise RuntimeError("the feeder died during the soak") from task.exception()
        wall = time.monotonic() - t0
        task.cancel()
        if run.job.state.value != "done":
            raise RuntimeError(f"the run ended {run.job.state.value}: {run.job.error}")
    warm = [s for s in samples if s["n"] > args.warmup]
    series = {}
    for key in {**BOUNDS, **EXTRA_BOUNDS}:
        xs = [s["n"] for s in warm]
        ys = [s[key] for s in warm]
        idle_xs = [s["t"] for s in idle]
        series[key] = {
            "start": round(samples[0][key], 2) if samples else None,
            "after_warmup": round(warm[0][key], 2) if warm else None,
            "end": round(samples[-1][key], 2) if samples else None,
            "max": round(max(s[key] for s in samples), 2) if samples else None,
            # medians of the first and last few warm samples: a leak moves them, a file or
            # connection that is open just when one inspection ends does not
            "early_median": round(float(np.median(ys[:WINDOW])), 2) if ys else None,
            "late_median": round(float(np.median(ys[-WINDOW:])), 2) if ys else None,
            "slope_per_1000": round(slope_per_1000(xs, ys), 3),
            "bound_per_1000": {**BOUNDS, **EXTRA_BOUNDS}[key],
            # idle baseline: slope per the same wall time as 1,000 inspections took
            "idle_slope_per_1000_time": round(
                slope_per_1000(idle_xs, [s[key] for s in idle]) / 1000.0
                * (wall / max(1, len(samples))) * 1000.0, 3),
        }  # fmt: skip
        series[key]["ok"] = abs(series[key]["slope_per_1000"]) < {**BOUNDS, **EXTRA_BOUNDS}[key]
    decisions: dict[str, int] = {}
    for s in samples:
        decisions[str(s["decision"])] = decisions.get(str(s["decision"]), 0) + 1
    plot = _plot(samples, args.warmup, args.docs)
    return {"benchmark": "soak", "inspections": len(samples), "asked": args.inspections,
            "warmup": args.warmup,
            "wall_s": round(wall, 1), "per_inspection_s": round(wall / max(1, len(samples)), 3),
            "time_scale": args.time_scale, "policy": args.policy, "decisions": decisions,
            "series": series, "plot": None if plot is None else str(plot)}  # fmt: skip


def _plot(samples: list[dict[str, float]], warmup: int, docs: bool) -> Path | None:
    if not samples:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 1, figsize=(7, 7), sharex=True)
    n = [s["n"] for s in samples]
    for ax, key, label in zip(
        axes, BOUNDS, ("RSS, MB", "open files", "DB connections"), strict=True
    ):
        ax.plot(n, [s[key] for s in samples], lw=1)
        ax.axvline(warmup, color="grey", ls="--", lw=0.8)
        ax.set_ylabel(label)
    axes[-1].set_xlabel("inspections")
    axes[0].set_title("Soak: resources after each inspection (dashed: end of warm-up)")
    d = DOCS_DIR if docs else OUT_DIR
    d.mkdir(parents=True, exist_ok=True)
    path = d / "soak.png"
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--inspections", type=int, default=1000, help="inspections (10..10000)")
    p.add_argument("--warmup", type=int, default=100, help="inspections before the fit")
    p.add_argument(
        "--taught-every", type=int, default=4, help="every k-th object is the taught model (1..20)"
    )
    p.add_argument("--policy", default="top-only", help="recognition policy")
    p.add_argument("--time-scale", type=float, default=8.0, help="simulated s per wall s (1..20)")
    p.add_argument("--idle-s", type=float, default=10.0, help="idle baseline, s (1..300)")
    p.add_argument(
        "--max-wall-s",
        type=float,
        default=36_000.0,
        help="stop the run after this many wall seconds (60..86400)",
    )
    p.add_argument("--docs", action="store_true", help="write the plot to docs/")
    p.add_argument("--json", action="store_true", help="one JSON line on the last line")
    args = p.parse_args(argv)
    for name, v, lo, hi in (("--inspections", args.inspections, 10, 10_000),
                            ("--warmup", args.warmup, 0, args.inspections - 3),
                            ("--taught-every", args.taught_every, 1, 20),
                            ("--time-scale", args.time_scale, 1, 20), ("--idle-s", args.idle_s, 1, 300),
                            ("--max-wall-s", args.max_wall_s, 60, 86_400)):  # fmt: skip
        if not lo <= v <= hi:
            p.error(f"{name} must be in [{lo}, {hi}], got {v!r}")
    t0 = time.monotonic()

    def progress(msg: str) -> None:
        err.print(f"[{time.monotonic() - t0:6.1f} s] {msg}")

    r = asyncio.run(soak(args, progress))
    t = Table(title=f"Soak: {r['inspections']} inspections ({r['per_inspection_s']:.2f} s each, "
                    f"warm-up {r['warmup']})")  # fmt: skip
    for col in ("resource", "start", "after warm-up", "end", "max", "slope /1000", "bound /1000",
                "idle slope (same time)", "ok"):  # fmt: skip
        t.add_column(col, justify="right" if col != "resource" else "left")
    for key, s in r["series"].items():
        t.add_row(key, str(s["start"]), str(s["after_warmup"]), str(s["end"]), str(s["max"]),
                  f"{s['slope_per_1000']:+.3f}", f"< {s['bound_per_1000']:g}",
                  f"{s['idle_slope_per_1000_time']:+.3f}", "yes" if s["ok"] else "NO")  # fmt: skip
    out.print(t)
    out.print(f"decisions: {r['decisions']}; plot: {r['plot']}")
    if args.json:
        print(json.dumps(r))
    return 0


if __name__ == "__main__":
    sys.exit(main())
