"""Teach and inspect in the simulated cell (issue 14's targets), one process.

The twelve trainable catalogue entries are taught through the services the API calls
(``backend.recognition.teach``: 3d models, the top view at three camera rolls and both side
views, each object at the station at ``--teach-yaws`` object yaws of the teach plan
(:func:`backend.recognition.teach.teach_yaws_rad`), the operator turning it between rounds; the automatic threshold is chosen once, after
the last round of the last model, over every view), then objects (random catalogue entry, the two
untrained ones mixed in; random yaw, a few mm of lateral and along-belt jitter) are
inspected with :func:`backend.inspection.service.inspect_object`, what continuous operation
runs for each object:

* ``index``: the object stopped at the station; each object inspected with ``naive`` (the
  chapter's Figure 6, the baseline), ``two-views`` and ``best-next`` in turn, so the three
  policies see the same objects;
* ``constant``: the belt running at ``--belt-speed``; top view of the moving object, pose
  predicted forward with the belt travel (``two-views``); at ``--constant-time-scale``
  (real time by default: the vision's wall seconds are the belt's seconds);
* ``half light`` and ``colour cast``: index mode, ``two-views``, every light at half
  intensity / a warm cast (green x0.85, blue x0.6), with the empty-belt background
  grabbed again under that light (the models were taught under the normal light); each
  object is inspected with the light balance (the product's default: the views' channels
  scaled back to the teach light by the belt's colour, :mod:`vision.recognition.light`)
  and again without it (``... unbalanced``, the baseline; ``--no-light-baseline`` skips it);
* ``sort``: index mode, ``two-views``, picked and sorted; a pick counts when the object
  landed in its part's bin (the reject bin for untrained parts).

Errors are against the simulator's truth of the same relative motion (each model taught at
yaw 0 at the station, so its frame is the truth's).  Yaw errors only for parts without
rotational symmetry (not the wheels).  Run::

    .venv/bin/python -m benchmarks.inspection --objects 20 [--json]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import os
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console
from rich.table import Table

os.environ.setdefault("MUJOCO_GL", "egl")  # headless rendering, before MuJoCo loads

out = Console()
err = Console(stderr=True)

#: Catalogue kinds whose yaw is not defined by their outline (surfaces of revolution; the
#: rim's spoke or hole pattern repeats every 360/n degrees).  A kind, not a part: a wheel's
#: part is its own name (``wheel-steel``), so testing the part against ``{"wheel"}`` used to
#: count every wheel's yaw, the 180-degree "error" of ``wheel-steel`` (8 holes, 4 bolts)
#: among them.
SYMMETRIC = {"wheel"}


def _settings(tmp: Path, time_scale: float) -> Any:
    from backend.settings import Settings

    return Settings(
        database_url=f"sqlite+aiosqlite:///{tmp / 'bench.db'}",
        var_dir=tmp / "var",
        driver="sim",
        camera="sim",
        sim_demo=False,
        time_scale=time_scale,
        secret_key="bench-secret-0123456789abcdef",
        view3d_enabled=False,
        bootstrap_operator=False,
    )


async def _teach_all(
    rt: Any, names: list[str], yaws_deg: tuple[float, ...] = (0.0,)
) -> tuple[float, dict[str, Any]]:
    """Teach every model through the teach service, one round per object yaw (the operator
    turns the object on the belt between rounds; the first round is at yaw 0)."""
    from backend.recognition import models as msvc
    from backend.recognition import teach as tsvc
    from backend.recognition.index import IndexedModel
    from robot.sim.catalogue import CATALOGUE

    engine = rt.sim
    station = engine.config.layout.conveyor.station_s_m
    engine.configure_conveyor(running=False, mode="index", dwell_s=None)
    t0 = time.perf_counter()
    for k, name in enumerate(names):
        from robot.sim.gripper import suction_point

        # Height and grasp point from the part's drawing, as an engineer enters them (the
        # object frame is where it sat at the first teach round, yaw 0: the drawing's).
        row = await msvc.create_model(
            rt.database,
            msvc.ModelFields(
                name=name, part=CATALOGUE[name].base_of, kind="3d",
                height_m=float(CATALOGUE[name].geometry().bounds[1, 2]),
                grasp_obj=tuple(float(v) for v in suction_point(name)),  # type: ignore[arg-type]
                height_given=True, grasp_given=True,
            ),
        )  # fmt: skip
        rt.live_index.put_model(IndexedModel.of(row))
        for r, yaw_deg in enumerate(yaws_deg):
            yaw = math.radians(yaw_deg)
            engine.clear_objects()
            first = k == 0 and r == 0
            if not first:
                engine.spawn(name, s_m=station, yaw_rad=yaw)
            job = await tsvc.start_teach(
                cell=rt.cell,
                db=rt.database,
                live=rt.live_index,
                model_id=row.id,
                options=tsvc.TeachOptions(
                    background="grab" if first else "stored",
                    wait_s=60.0,
                    yaw_rad=yaw,
                    # one choice over every view, after the last round of the last model
                    threshold=k == len(names) - 1 and r == len(yaws_deg) - 1,
                ),
                store=rt.teach_backgrounds,
            )
            if first:
                while "waiting for an object" not in job.message and not job.task.done():
                    await asyncio.sleep(0.1)
                engine.spawn(name, s_m=station, yaw_rad=yaw)
            await rt.jobs.wait(job)
            if job.state.value != "done":
                raise RuntimeError(f"teaching {name} {job.state.value}: {job.error}")
            last = job.result["threshold"]
        err.print(f"[teach {k + 1}/{len(names)}] {name}: {len(yaws_deg)} rounds")
    engine.clear_objects()
    return time.perf_counter() - t0, last


def _errors(row: dict[str, Any], kind: str) -> tuple[float | None, float | None]:
    """Position (mm) and yaw (deg) errors; at constant speed those of the pose predicted
    forward by the belt's travel against the truth moved forward by the same travel."""
    if row["pose"] is None or row["truth"] is None:
        return None, None
    T = np.array(row["pose"]["at_exposure"])
    Tt = np.array(row["truth"]["T_base_obj"])
    travel = row["pose"].get("predicted_travel_m")
    if travel is not None:
        T = np.array(row["pose"]["T_base_obj"])
        Tt[1, 3] += float(travel)
    return pose_errors(T, Tt, kind in SYMMETRIC)


def pose_errors(T: Any, T_true: Any, symmetric: bool = False) -> tuple[float, float | None]:
    """Position error on the belt plane (mm) and yaw error (deg; None for a part with
    rotational symmetry) of the pose ``T`` against ``T_true`` (4x4 each)."""
    pos = float(np.linalg.norm(T[:2, 3] - T_true[:2, 3]) * 1e3)
    if symmetric:
        return pos, None
    d = math.atan2(T[1, 0], T[0, 0]) - math.atan2(T_true[1, 0], T_true[0, 0])
    return pos, abs(math.degrees(math.remainder(d, 2 * math.pi)))


async def _inspect(service: Any, ctx: Any, opts: Any) -> dict[str, Any]:
    """One inspection's row; an object the search never found counts as a failed one here
    (the product stores no row for a wait that ends without a part)."""
    from backend.inspection.errors import NoObject

    try:
        return dict(await service.inspect_object(ctx, opts))
    except NoObject as exc:
        return {"decision": "failed", "model": None, "score": None, "scores": {},
                "viewpoints_visited": [], "durations": {}, "pose": None, "pick": None,
                "truth": None, "reason": f"no_object: {exc.detail}"}  # fmt: skip


def _record(
    cond: str, policy: str, name: str, row: dict[str, Any], extra: dict[str, Any]
) -> dict[str, Any]:
    from robot.sim.catalogue import CATALOGUE

    entry = CATALOGUE[name]
    pos, yaw = _errors(row, entry.kind)
    n = max(1, len(row["viewpoints_visited"]))
    d = row["durations"]
    vision = sum(d.get(k, 0.0) for k in ("segment", "features", "match", "decide"))
    return {
        "condition": cond,
        "policy": policy,
        "name": name,
        "trainable": entry.trainable,
        "decision": row["decision"],
        "model": row["model"],
        "correct": (row["decision"] == "recognized" and row["model"] == name)
        if entry.trainable
        else row["decision"] == "unknown",
        "views": len(row["viewpoints_visited"]),
        # the pose's second top view (the first rested on too little), and a correctly
        # named object left without a pose (too little in both top views)
        "second_top_view": list(row["viewpoints_visited"]).count(1) > 1,
        "pose_refused": entry.trainable
        and row["decision"] == "recognized"
        and row["model"] == name
        and row["pose"] is None,
        "pos_err_mm": pos,
        "yaw_err_deg": yaw,
        "vision_per_view_s": vision / n,
        "cycle_s": sum(v for k, v in d.items() if k != "wait"),
        "stages": {k: v for k, v in d.items()},
        "reason": row["reason"],
        "pose_hypotheses": _hypotheses(row),
        **extra,
    }


def _hypotheses(row: dict[str, Any]) -> list[dict[str, Any]]:
    """The pose's groups of agreeing views with their errors against the truth."""
    if row["pose"] is None or row["truth"] is None:
        return []
    Tt = np.array(row["truth"]["T_base_obj"])
    yaw_t = math.atan2(Tt[1, 0], Tt[0, 0])
    out = []
    for h in row["pose"].get("hypotheses", []):
        pos = float(np.linalg.norm(np.array(h["position_m"][:2]) - Tt[:2, 3]) * 1e3)
        dyaw = abs(math.degrees(math.remainder(h["yaw_rad"] - yaw_t, 2 * math.pi)))
        out.append({"pos_err_mm": round(pos, 2), "yaw_err_deg": round(dyaw, 2),
                    **{k: h[k] for k in ("views", "correspondences", "silhouette_iou", "chosen")}})  # fmt: skip
    return out


def _bin_for(engine: Any, name: str) -> str:
    from robot.sim.catalogue import CATALOGUE

    entry = CATALOGUE[name]
    for b in engine.config.layout.bins:
        if (b.reject and not entry.trainable) or (entry.trainable and entry.base_of in b.parts):
            return b.name
    raise KeyError(name)


async def _run(args: argparse.Namespace) -> dict[str, Any]:
    from backend.db.migrate import upgrade
    from backend.inspection import service
    from backend.inspection.pose import warm_feature_heights
    from backend.runtime import CellRuntime
    from robot.sim.catalogue import CATALOGUE

    tmp = Path(tempfile.mkdtemp(prefix="bench-inspect-"))
    settings = _settings(tmp, args.time_scale)
    cached = _load_taught(args, tmp / "bench.db")
    await asyncio.to_thread(upgrade, settings.database_url)
    rng = np.random.default_rng(args.seed)
    trained = [n for n, e in CATALOGUE.items() if e.trainable]
    untrained = [n for n, e in CATALOGUE.items() if not e.trainable]
    rows: list[dict[str, Any]] = []
    async with CellRuntime(settings, view3d=False) as rt:
        engine = rt.sim
        spec = engine.config.layout.conveyor
        from backend.recognition.teach import teach_yaws_rad

        yaws = tuple(math.degrees(y) for y in teach_yaws_rad(args.teach_yaws))
        if cached is not None and cached["descriptor_version"] != rt.live_index.version:
            err.print(
                f"[taught-db] {args.taught_db} holds descriptor version "
                f"{cached['descriptor_version']!r}, this build {rt.live_index.version!r}: "
                "use another file or delete it to teach again"
            )
            raise SystemExit(2)
        if cached is not None:
            teach_s, threshold = 0.0, cached["threshold"]
            err.print(f"[taught-db] {len(trained)} models from {args.taught_db} "
                      f"(taught by commit {cached['commit']}; teaching skipped)")  # fmt: skip
        else:
            teach_s, threshold = await _teach_all(rt, trained, yaws)
            if args.taught_db is not None:
                await _save_taught(args, tmp / "bench.db", threshold, rt.live_index.version)
        err.print(f"threshold: {threshold}")
        ctx = await service.context(rt)
        # as a continuous run does before its first object (service.start_run)
        t_warm = time.perf_counter()
        warmed = await warm_feature_heights(ctx)
        err.print(f"taught top views triangulated: {warmed} models in "
                  f"{time.perf_counter() - t_warm:.1f} s")  # fmt: skip

        def pick_name() -> str:
            if args.parts:  # a diagnostic run on a few catalogue entries
                return str(rng.choice(args.parts))
            return str(rng.choice(untrained if rng.uniform() < 0.15 else trained))

        async def index_object(
            cond: str, policies: tuple[str, ...], sort: bool = False, baseline: bool = False
        ) -> None:
            name = pick_name()
            engine.clear_objects()
            engine.configure_conveyor(running=False, mode="index", dwell_s=None)
            engine.spawn(
                name,
                s_m=spec.station_s_m + float(rng.uniform(-0.004, 0.004)),
                lateral_m=float(rng.uniform(-0.004, 0.004)),
                yaw_rad=float(rng.uniform(-math.pi, math.pi)),
            )
            runs = [(cond, p, True) for p in policies]
            if baseline:  # the same object without the light balance
                runs += [(cond + " unbalanced", p, False) for p in policies]
            for cond_label, policy, balance in runs:
                opts = service.InspectOptions(
                    policy=policy, sort=sort, wait_s=20.0, balance_light=balance
                )
                row = await _inspect(service, ctx, opts)
                extra: dict[str, Any] = {}
                if sort:
                    landed = engine.landings()[-1] if engine.landings() else None
                    extra = {
                        "pick_ok": bool(row["pick"] and row["pick"].get("ok")),
                        "pick_right_bin": landed is not None
                        and landed.place == _bin_for(engine, name)
                        and bool(row["pick"] and row["pick"].get("ok")),
                        "pick_reason": (row["pick"] or {}).get("reason", ""),
                    }
                rows.append(_record(cond_label, policy, name, row, extra))
                r = rows[-1]
                err.print(
                    f"[{cond_label} {len(rows)}] {policy}: {name} -> {r['decision']} {r['model']} "
                    f"views={r['views']} pos={r['pos_err_mm']} {r['reason'][:60]}"
                )

        for k in range(args.objects):
            if k % 10 == 0:
                err.print(f"[index] object {k + 1} of {args.objects}")
            await index_object("index", args.policies)
        # constant belt speed: the empty belt's background registered to its travel first
        if args.objects_constant:
            engine.clear_objects()
            t_bg = time.perf_counter()
            await service.grab_belt_background(rt)
            err.print(f"[constant] belt background grabbed in {time.perf_counter() - t_bg:.0f} s")
            # The belt runs on while the vision computes (wall seconds): at --time-scale 20
            # one second of vision is 20 s of belt (1-2 m at 0.05-0.1 m/s), not the cell's
            # timing, and the object leaves the belt before its side views.  The arm and the
            # belt run at --constant-time-scale for this condition (real time by default).
            scale_before = engine.time_scale
            engine.time_scale = args.constant_time_scale
        for _ in range(args.objects_constant):
            name = pick_name()
            engine.clear_objects()
            engine.configure_conveyor(running=False, mode="continuous")
            engine.spawn(
                name,
                s_m=spec.station_s_m - 0.15,
                lateral_m=float(rng.uniform(-0.004, 0.004)),
                yaw_rad=float(rng.uniform(-math.pi, math.pi)),
            )
            engine.configure_conveyor(running=True, speed_m_s=args.belt_speed, mode="continuous")
            row = await _inspect(
                service, ctx, service.InspectOptions(policy="two-views", wait_s=20.0)
            )
            engine.configure_conveyor(running=False)
            # How far from the station the top view saw it (the truth at the exposure): the
            # camera's frames come a belt travel apart, and the pose's error grows with it.
            off = None
            if row["truth"] is not None:
                off = (row["truth"]["T_base_obj"][1][3] - spec.station_point[1]) * 1e3
            rows.append(_record("constant", "two-views", name, row, {"exposure_offset_mm": off}))
            r = rows[-1]
            err.print(
                f"[constant {len(rows)}] {name} -> {row['decision']} {row['model']} "
                f"views={r['views']} pos={r['pos_err_mm']} yaw={r['yaw_err_deg']} "
                f"offset_mm={off} {row['reason'][:60]}"
            )
        if args.objects_constant:
            engine.time_scale = scale_before
        # lights
        base = engine._light_base.copy()  # the benchmark changes the lights' colour directly
        for cond in ("half light", "colour cast"):
            if cond == "half light":
                for light in engine.lights():
                    engine.set_light(light, 0.5)
            else:
                for light in engine.lights():
                    engine.set_light(light, 1.0)
                engine._light_base[:] = base * np.array([1.0, 0.85, 0.6], dtype=np.float32)
            engine.clear_objects()
            await service.grab_background(rt)
            for k in range(args.objects_light):
                if k % 10 == 0:
                    err.print(f"[{cond}] object {k + 1} of {args.objects_light}")
                await index_object(cond, ("two-views",), baseline=args.light_baseline)
        engine._light_base[:] = base
        engine.clear_objects()
        await service.grab_background(rt)
        for _ in range(args.objects_sort):
            await index_object("sort", ("two-views",), sort=True)
    return {"teach_s": teach_s, "rows": rows, "n_models": len(trained), "threshold": threshold}


def _taught_meta(path: Path) -> Path:
    return path.with_name(path.name + ".json")


def _load_taught(args: argparse.Namespace, db: Path) -> dict[str, Any] | None:
    """The taught database of an earlier run with the same teach settings, copied to ``db``
    (``--taught-db``: teaching the twelve models takes about ten minutes; the cache is for
    iterating on inspection, not for figures after a change to teaching)."""
    import shutil

    path = args.taught_db
    if path is None or not path.exists():
        return None
    meta = json.loads(_taught_meta(path).read_text())
    if meta["teach_yaws"] != args.teach_yaws or meta["time_scale"] != args.time_scale:
        err.print(
            f"[taught-db] {path} was taught with --teach-yaws {meta['teach_yaws']} "
            f"--time-scale {meta['time_scale']}: use another file or delete it"
        )
        raise SystemExit(2)
    shutil.copyfile(path, db)
    return meta


async def _save_taught(
    args: argparse.Namespace, db: Path, threshold: dict[str, Any], version: str
) -> None:
    import sqlite3
    import subprocess

    commit = (
        subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, check=False
        ).stdout.strip()
        or "unknown"
    )
    args.taught_db.parent.mkdir(parents=True, exist_ok=True)
    # A consistent copy while the runtime holds the file open (SQLite's online backup).
    src, dst = sqlite3.connect(db), sqlite3.connect(args.taught_db)
    try:
        src.backup(dst)
    finally:
        src.close()
        dst.close()
    meta = {"teach_yaws": args.teach_yaws, "time_scale": args.time_scale, "commit": commit,
            "descriptor_version": version, "threshold": threshold}  # fmt: skip
    _taught_meta(args.taught_db).write_text(json.dumps(meta, default=str))
    err.print(f"[taught-db] saved to {args.taught_db}")


def _pct(x: list[bool]) -> float | None:
    return None if not x else 100.0 * sum(x) / len(x)


def _q(x: list[float], q: float) -> float | None:
    return None if not x else float(np.percentile(x, q))


def summarise(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One line per (condition, policy)."""
    out_rows = []
    keys = sorted({(r["condition"], r["policy"]) for r in rows}, key=lambda k: (k[0] != "index", k))
    for cond, policy in keys:
        rs = [r for r in rows if r["condition"] == cond and r["policy"] == policy]
        tr = [r for r in rs if r["trainable"]]
        un = [r for r in rs if not r["trainable"]]
        pos = [r["pos_err_mm"] for r in tr if r["pos_err_mm"] is not None]
        yaw = [r["yaw_err_deg"] for r in tr if r["yaw_err_deg"] is not None]
        stages: dict[str, float] = {}
        for r in rs:
            for k, v in r["stages"].items():
                stages[k] = stages.get(k, 0.0) + v / len(rs)
        out_rows.append(
            {
                "condition": cond,
                "policy": policy,
                "objects": len(rs),
                "named_pct": _pct([r["correct"] for r in tr]),
                "unknown_pct": _pct([r["correct"] for r in un]),
                "pos_err_mm_p50": _q(pos, 50),
                "pos_err_mm_max": None if not pos else max(pos),
                "yaw_err_deg_p50": _q(yaw, 50),
                "yaw_err_deg_max": None if not yaw else max(yaw),
                "views_mean": float(np.mean([r["views"] for r in rs])),
                "second_top_views": sum(r["second_top_view"] for r in rs),
                "poses_refused": sum(r["pose_refused"] for r in rs),
                "vision_per_view_ms_p95": 1e3
                * (_q([r["vision_per_view_s"] for r in rs], 95) or 0.0),
                "cycle_s_p50": _q([r["cycle_s"] for r in rs], 50),
                "cycle_s_p95": _q([r["cycle_s"] for r in rs], 95),
                "stages_mean_s": {k: round(v, 3) for k, v in stages.items()},
                "picks_right_bin_pct": _pct(
                    [r["pick_right_bin"] for r in rs if "pick_right_bin" in r]
                ),
            }
        )
    return out_rows


def _f(v: float | None, fmt: str = "{:.1f}") -> str:
    return "-" if v is None else fmt.format(v)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--objects", type=int, default=20, help="index-mode objects (x3 policies)")
    ap.add_argument("--objects-constant", type=int, default=None)
    ap.add_argument("--objects-light", type=int, default=None)
    ap.add_argument("--objects-sort", type=int, default=None)
    ap.add_argument("--belt-speed", type=float, default=0.05, help="m/s, constant mode")
    ap.add_argument("--time-scale", type=float, default=20.0)
    ap.add_argument("--constant-time-scale", type=float, default=1.0,
                    help="time scale of the constant-speed condition (the vision runs in wall "
                         "seconds while the belt moves: real time by default)")  # fmt: skip
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument(
        "--teach-yaws", type=int, default=8, help="teach rounds per model (object yaws)"
    )
    ap.add_argument(
        "--policies", default="naive,two-views,best-next",
        help="index-mode policies, comma-separated (each sees the same objects)",
    )  # fmt: skip
    ap.add_argument(
        "--taught-db", type=Path, default=None,
        help="SQLite file: reuse the models taught by an earlier run with the same "
        "--teach-yaws (taught and saved there when it does not exist)",
    )  # fmt: skip
    ap.add_argument(
        "--no-light-baseline", dest="light_baseline", action="store_false",
        help="under half light and the colour cast, do not inspect each object a second "
        "time without the light balance (the baseline)",
    )  # fmt: skip
    ap.add_argument(
        "--parts", default="",
        help="comma-separated catalogue names: inspect only these (every trainable entry is "
        "still taught); default: the trained ones with the untrained mixed in",
    )  # fmt: skip
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--rows", action="store_true", help="with --json: every inspection's row")
    args = ap.parse_args(argv)
    if not 0 <= args.objects <= 2000:
        ap.error(f"--objects must be in 0..2000, got {args.objects}")
    from vision.recognition.views import POLICIES

    args.policies = tuple(p.strip() for p in args.policies.split(",") if p.strip())
    bad = [p for p in args.policies if p not in POLICIES]
    if bad or not args.policies:
        ap.error(f"--policies: unknown {bad or 'empty'}; valid: {', '.join(POLICIES)}")
    from robot.sim.catalogue import CATALOGUE

    args.parts = tuple(p.strip() for p in args.parts.split(",") if p.strip())
    unknown_parts = [p for p in args.parts if p not in CATALOGUE]
    if unknown_parts:
        ap.error(f"--parts: not in the catalogue: {unknown_parts}; valid: {', '.join(CATALOGUE)}")
    if not (0.0 < args.belt_speed <= 0.5):
        ap.error(f"--belt-speed must be in (0, 0.5] m/s, got {args.belt_speed}")
    if not 1 <= args.teach_yaws <= 12:
        ap.error(f"--teach-yaws must be in 1..12, got {args.teach_yaws}")
    if not (1.0 <= args.time_scale <= 100.0):
        ap.error(f"--time-scale must be in [1, 100], got {args.time_scale}")
    if not (0.1 <= args.constant_time_scale <= 100.0):
        ap.error(f"--constant-time-scale must be in [0.1, 100], got {args.constant_time_scale}")
    for k in ("objects_constant", "objects_light", "objects_sort"):
        v = getattr(args, k)
        setattr(args, k, max(1, args.objects // 2) if v is None else v)
        if not 0 <= getattr(args, k) <= 2000:
            ap.error(f"--{k.replace('_', '-')} must be in 0..2000")
    t0 = time.perf_counter()
    res = asyncio.run(_run(args))
    summary = summarise(res["rows"])
    table = Table(
        title=f"Inspection in the simulator ({res['n_models']} models taught in {res['teach_s']:.0f} s)"
    )
    for col in ("condition", "policy", "n", "named %", "unknown %", "pos mm p50/max",
                "yaw deg p50/max", "no pose", "views", "2nd top", "vision/view ms p95", "cycle s p50/p95", "right bin %"):  # fmt: skip
        table.add_column(col)
    for s in summary:
        table.add_row(
            s["condition"], s["policy"], str(s["objects"]), _f(s["named_pct"]), _f(s["unknown_pct"]),
            f"{_f(s['pos_err_mm_p50'], '{:.2f}')}/{_f(s['pos_err_mm_max'], '{:.2f}')}",
            f"{_f(s['yaw_err_deg_p50'], '{:.2f}')}/{_f(s['yaw_err_deg_max'], '{:.2f}')}",
            str(s["poses_refused"]), f"{s['views_mean']:.2f}", str(s["second_top_views"]),
            f"{s['vision_per_view_ms_p95']:.0f}",
            f"{_f(s['cycle_s_p50'], '{:.2f}')}/{_f(s['cycle_s_p95'], '{:.2f}')}",
            _f(s["picks_right_bin_pct"]),
        )  # fmt: skip
    out.print(table)
    for s in summary:
        out.print(f"{s['condition']:>12} {s['policy']:>10} stages (mean s): {s['stages_mean_s']}")
    th = res["threshold"]
    out.print(f"automatic threshold after the last teach: {th['threshold']} ({th['reason']})")
    out.print(f"confusable from the top: {th['confusable_from_top'] or 'none'}")
    wrong = [r for r in res["rows"] if not r["correct"]]
    for r in wrong[:20]:
        out.print(
            f"  wrong: {r['condition']} {r['policy']} {r['name']} -> {r['decision']} {r['model']}: {r['reason']}"
        )
    if args.json:
        print(json.dumps({"summary": summary, "teach_s": res["teach_s"], "wall_s": time.perf_counter() - t0,
                          "threshold": res["threshold"],
                          "wrong": wrong, "rows": res["rows"] if args.rows else None},
                         default=str))  # fmt: skip


if __name__ == "__main__":
    main()
