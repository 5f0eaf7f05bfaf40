"""Genuine and impostor scores of the cell's recognition at random object yaw (issue 14).

    python -m benchmarks.recognition_yaw [--json] [--objects 12] [--queries 3] [--teach-yaws 4]
        [--seed 0] [--cache DIR] [--no-baseline] [--no-roi] [--teach-spread plan|half] [--teach-yaws-deg 0,30,...]

Procedure (simulated cell, rendered afresh, no database): every trainable catalogue entry
is taught as the teach job teaches it (:func:`backend.recognition.teach.plan_shots`: the
top view at the camera rolls of ``TOP_ROLLS_RAD`` and both side views, segmented by the
active contour from the empty-belt background, at ``--teach-yaws`` object yaws as the teach plan spreads them (:func:`backend.recognition.teach.teach_yaws_rad`:
evenly over the whole turn; ``--teach-spread half``: evenly over a half turn;
``--teach-yaws-deg``: any others); the automatic threshold is chosen from those views
(:func:`vision.recognition.choose_threshold`, as after a teach).  Then each entry (and the
two untrained ones) is put back at random yaws with a few mm of jitter and inspected as
:func:`backend.inspection.service.inspect_object` does: the top view segmented, side views
planned at the station point, each side query matched inside the image of the space the
object found from the top can occupy (:func:`vision.segmentation.roi.side_roi`, the
service's function, up to the tallest taught model's height; ``--no-roi``: the whole frame,
as before), decided by :func:`vision.recognition.recognise_views` with the ``two-views``
policy.  The side queries' feature counts and the regions' share of the frame are printed.

Printed (rich table, ``--json`` one line): the thresholds chosen per viewpoint and the
named / unknown rates, for the rule of :func:`vision.recognition.choose_threshold` and, as
baselines in the same run on the same images, (a) the threshold rule before issue 14's
first fix (twins' scores kept among the impostors: the top threshold at the genuine level)
and (b) the features and decision before its second fix (no ``smooth_px`` before SIFT, no
colour tie-break of the twins; its own index and threshold); the wrong decisions with the
own-model top score against its bar and the side scores.
Rendering is the slow part: ``--cache DIR`` keeps the images for a rerun.
"""

from __future__ import annotations

import argparse
import asyncio
import functools
import json
import math
import pickle
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console
from rich.table import Table

TWINS = {"wheel-5spoke": "wheel-5spoke-redband", "wheel-5spoke-redband": "wheel-5spoke"}


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def _cached(cache: Path | None, key: str, make: Any) -> Any:
    """``make()``, kept in ``cache`` under ``key`` (rendering is the slow part)."""
    if cache is None:
        return make()
    f = cache / (key.replace("/", "_") + ".pkl")
    if f.exists():
        with f.open("rb") as fh:
            return pickle.load(fh)
    got = make()
    cache.mkdir(parents=True, exist_ok=True)
    with f.open("wb") as fh:
        pickle.dump(got, fh)
    return got


def render_teach(
    engine: Any, name: str, yaw: float, shots: Any, backgrounds: dict[Any, Any]
) -> list[tuple[Any, Any]]:
    """The teach shots of ``name`` put on the station at ``yaw``: each shot's image and the
    active contour's region in it (from that shot's empty-belt background)."""
    from backend.recognition.segment import segment_object
    from robot.sim.imaging import capture

    engine.clear_objects()
    engine.spawn(name, s_m=engine.config.layout.conveyor.station_s_m, yaw_rad=yaw)
    got = []
    for s in shots:
        rgb = capture(engine, s.q).rgb
        got.append((rgb, segment_object(rgb, backgrounds[s.key]).mask))
    return got


def render_query(
    engine: Any,
    name: str,
    yaw: float,
    ds: float,
    dl: float,
    shot: Any,
    backgrounds: dict[Any, Any],
) -> tuple[Any, Any]:
    """``name`` put alone on the belt ``ds`` along from the station and ``dl`` across,
    turned by ``yaw``, seen from ``shot``: the image and the active contour's region."""
    from backend.recognition.segment import segment_object
    from robot.sim.imaging import capture

    engine.clear_objects()
    s_m = engine.config.layout.conveyor.station_s_m + ds
    engine.spawn(name, s_m=s_m, lateral_m=dl, yaw_rad=yaw)
    rgb = capture(engine, shot.q).rgb
    return rgb, segment_object(rgb, backgrounds[shot.key])


def run(
    *,
    cache: Path | None = None,
    objects: int = 12,
    queries: int = 3,
    teach_yaws: int = 4,
    policy: str = "two-views",
    seed: int = 0,
    names: list[str] | None = None,
    untrained: list[str] | None = None,
    baseline: bool = True,
    roi: bool = True,
    spread: str = "plan",
    teach_yaws_deg: list[float] | None = None,
) -> dict[str, Any]:
    """Teach, choose the threshold and inspect (module docstring); ``names`` and
    ``untrained`` replace the catalogue's trainable (first ``objects``) and untrained
    entries."""
    from backend.hardware import headless_mujoco

    headless_mujoco()
    from backend.calibration.autoplan import NOMINAL_T_EE_CAM
    from backend.planning import plan_shots
    from backend.recognition.index import FEATURE_OPTIONS
    from backend.recognition.teach import TOP_ROLLS_RAD, teach_yaws_rad
    from robot.kinematics import T_base_ee
    from robot.sim import CATALOGUE, SimEngine
    from robot.sim.imaging import capture
    from robot.viewpoints import VIEW_NAMES, plan_viewpoints
    from vision.recognition import ViewIndex, choose_threshold, recognise_views
    from vision.recognition.views import colour_support
    from vision.segmentation.roi import height_bound, side_query, side_roi

    rng = np.random.default_rng(seed)
    engine = SimEngine()
    try:
        belt = engine.config.layout.conveyor
        if names is None:
            names = [n for n, e in CATALOGUE.items() if e.trainable][:objects]
        if untrained is None:
            untrained = [n for n, e in CATALOGUE.items() if not e.trainable]
        point = np.asarray(belt.station_point, dtype=np.float64)
        T_ee_cam = np.asarray(NOMINAL_T_EE_CAM)
        shots = plan_shots(
            point, (1, 2, 3), T_ee_cam=T_ee_cam, object_height_m=0.1, top_rolls_rad=TOP_ROLLS_RAD
        )

        def empty() -> dict[Any, Any]:
            engine.clear_objects()
            return {s.key: capture(engine, s.q).rgb for s in shots}

        backgrounds = _cached(cache, "backgrounds", empty)
        options = dict(FEATURE_OPTIONS.get("sift", {}))
        index = ViewIndex("sift", feature_options=options)
        # Baseline (b): the extraction before issue 14's smoothing (module docstring).
        old_options = {k: v for k, v in options.items() if k != "smooth_px"}
        old_index = ViewIndex("sift", feature_options=old_options) if baseline else None
        if teach_yaws_deg is not None:  # an experiment's own yaws
            yaws = [math.radians(y) for y in teach_yaws_deg]
        elif spread == "half":  # evenly over a half turn (measured against the plan)
            yaws = [math.pi * k / teach_yaws for k in range(teach_yaws)]
        else:  # the teach job's plan (teach_yaws_rad)
            yaws = list(teach_yaws_rad(teach_yaws))
        t0 = time.perf_counter()
        for k, name in enumerate(names):
            _log(f"  teaching {k + 1}/{len(names)}: {name}")
            for yaw in yaws:
                key = f"teach-{name}-{math.degrees(yaw):.1f}"

                render = functools.partial(render_teach, engine, name, yaw, shots, backgrounds)
                for s, (rgb, mask) in zip(shots, _cached(cache, key, render), strict=True):
                    index.add(name, rgb, viewpoint=s.viewpoint, mask=mask.astype(np.uint8))
                    if old_index is not None:
                        old_index.add(name, rgb, viewpoint=s.viewpoint, mask=mask.astype(np.uint8))
        teach_s = time.perf_counter() - t0
        _log(f"  choosing the threshold over {len(index)} views")
        t1 = time.perf_counter()
        choice = choose_threshold(index)
        choose_s = time.perf_counter() - t1
        # Baseline in the same run: the rule before the fix (twins' scores kept in).
        before = choose_threshold(index, exclude_twins=False) if baseline else None
        old_choice = choose_threshold(old_index) if old_index is not None else None
        top = shots[0]
        # The service's camera model and mounting without calibrations (the simulator's
        # nominal ones) and the side viewpoints planned from the station point (as rendered).
        camera = engine.config.camera.pinhole
        T_ee_cam_model = np.asarray(engine.config.camera.T_ee_cam, dtype=np.float64)
        T_cam_top = T_base_ee(np.asarray(top.q)) @ T_ee_cam_model
        T_cam_sides = {
            vp: T_base_ee(
                np.asarray(plan_viewpoints(point, T_ee_cam=T_ee_cam, views=(VIEW_NAMES[vp - 1],),
                                           object_height_m=0.1).views[0].q)
            ) @ T_ee_cam_model
            for vp in (2, 3)
        }  # fmt: skip
        # Height bound as the service's: the taught models' stored heights (the inspection
        # benchmark stores the catalogue's height with each model it creates).
        roi_height = height_bound(float(CATALOGUE[n].geometry().bounds[1, 2]) for n in names)
        surface_z = float(belt.surface_z_m)
        rows: list[dict[str, Any]] = []
        pool = [(n, True) for n in names] + [(n, False) for n in untrained]
        for name, trainable in pool:
            for _ in range(queries if trainable else max(1, queries)):
                yaw = float(rng.uniform(-math.pi, math.pi))
                ds, dl = (float(v) for v in rng.uniform(-0.004, 0.004, size=2))
                key = f"query-{name}-{yaw:.6f}-{ds:.6f}-{dl:.6f}"

                def shoot(
                    name: str = name, yaw: float = yaw, ds: float = ds, dl: float = dl
                ) -> Any:
                    rgb, region = render_query(engine, name, yaw, ds, dl, top, backgrounds)
                    sides = {}
                    for vp in (2, 3):
                        plan = plan_viewpoints(
                            point, T_ee_cam=T_ee_cam, views=(VIEW_NAMES[vp - 1],),
                            object_height_m=0.1,
                        )  # fmt: skip
                        sides[vp] = capture(engine, plan.views[0].q).rgb
                    return rgb, region.mask, sides

                rgb, qmask, sides = _cached(cache, key, shoot)

                rois = {}
                if roi:
                    for vp in (2, 3):
                        rois[vp] = side_roi(
                            qmask, camera=camera, T_base_cam_top=T_cam_top,
                            T_base_cam_side=T_cam_sides[vp], surface_z_m=surface_z,
                            height_m=roi_height, image_shape=sides[vp].shape[:2],
                        )  # fmt: skip

                def look(vp: int, rgb: Any = rgb, qmask: Any = qmask, sides: Any = sides,
                         rois: Any = rois) -> Any:  # fmt: skip
                    if vp == 1:
                        return rgb, qmask.astype(np.uint8)
                    return side_query(sides[vp], rois[vp]) if vp in rois else sides[vp]

                t2 = time.perf_counter()
                res = asyncio.run(recognise_views(look, index, policy=policy, threshold=choice))
                dt = time.perf_counter() - t2

                def correct(r: Any, name: str = name, trainable: bool = trainable) -> bool:
                    if trainable:
                        return bool(r.decision == "recognized" and r.model == name)
                    return bool(r.decision != "recognized")

                ok_before = ok_old = None
                if before is not None:
                    old = asyncio.run(recognise_views(look, index, policy=policy, threshold=before))
                    ok_before = correct(old)
                if old_index is not None:
                    old = asyncio.run(
                        recognise_views(look, old_index, policy=policy, threshold=old_choice,
                                        colour_tiebreak=False)
                    )  # fmt: skip
                    ok_old = correct(old)
                top_r = res.views[0]
                at1 = choice.at(1)
                own = float(top_r.scores.get(name, 0.0))
                ok = (
                    res.decision == "recognized" and res.model == name
                    if trainable
                    else res.decision != "recognized"
                )
                rows.append(
                    {
                        "name": name,
                        "trainable": trainable,
                        "yaw_deg": round(math.degrees(yaw), 1),
                        "decision": res.decision,
                        "model": res.model,
                        "ok": ok,
                        "ok_before": ok_before,
                        "ok_before_smooth_colour": ok_old,
                        "views": res.n_views,
                        "own_top": round(own, 3),
                        "own_top_bar": round(at1.per_model.get(name, at1.threshold), 3),
                        "best_top": top_r.best_model,
                        "best_top_score": round(float(top_r.score), 3),
                        "fused": {k: round(float(v), 3) for k, v in res.scores.items() if v > 0},
                        "side": [
                            {k: round(float(v), 3) for k, v in r.scores.items() if v > 0}
                            for r in res.views[1:]
                        ],
                        "side_features": [int(r.n_features) for r in res.views[1:]],
                        "side_roi": {
                            vp: (round(r.fraction, 3), r.reason) for vp, r in rois.items()
                        },
                        "colour": {
                            k: round(v, 4)
                            for k, v in colour_support(
                                index,
                                list(res.views),
                                [None if vp == 1 else sides[vp] for vp in res.viewpoints],
                                [k for k, v in res.scores.items() if v > 0],
                            ).items()
                        },
                        "seconds": round(dt, 3),
                    }
                )
                r = rows[-1]
                _log(
                    f"  {name} yaw {r['yaw_deg']:7.1f}: {r['decision']} {r['model']} "
                    f"views={r['views']} own_top={r['own_top']} bar={r['own_top_bar']} "
                    f"side={r['side']} colour={r['colour']} side_features={r['side_features']}"
                )
        tr = [r for r in rows if r["trainable"]]
        un = [r for r in rows if not r["trainable"]]
        return {
            "teach_yaws": teach_yaws,
            "views": len(index),
            "teach_s": teach_s,
            "choose_s": choose_s,
            "threshold": choice.threshold,
            "per_viewpoint": choice.per_viewpoint,
            "candidate_viewpoint": choice.candidate_viewpoint,
            "per_model_top": dict(choice.at(1).per_model),
            "genuine_p10_p50": [
                float(np.percentile(choice.genuine, 10)),
                float(np.median(choice.genuine)),
            ],
            "impostor_p50_p99": [
                float(np.median(choice.impostor)),
                float(np.percentile(choice.impostor, 99)),
            ],
            "threshold_before": None if before is None else before.per_viewpoint,
            "named_pct_before": None
            if before is None
            else 100.0 * sum(bool(r["ok_before"]) for r in tr) / max(1, len(tr)),
            "unknown_pct_before": None
            if before is None
            else 100.0 * sum(bool(r["ok_before"]) for r in un) / max(1, len(un)),
            "options": options,
            "threshold_before_smooth_colour": None
            if old_choice is None
            else old_choice.per_viewpoint,
            "named_pct_before_smooth_colour": None
            if old_choice is None
            else 100.0 * sum(bool(r["ok_before_smooth_colour"]) for r in tr) / max(1, len(tr)),
            "unknown_pct_before_smooth_colour": None
            if old_choice is None
            else 100.0 * sum(bool(r["ok_before_smooth_colour"]) for r in un) / max(1, len(un)),
            "named_pct": 100.0 * sum(r["ok"] for r in tr) / max(1, len(tr)),
            "unknown_pct": 100.0 * sum(r["ok"] for r in un) / max(1, len(un)),
            "mean_views": float(np.mean([r["views"] for r in rows])),
            "side_roi": roi,
            "teach_spread": spread,
            "teach_yaws_deg": [round(math.degrees(y), 1) for y in yaws],
            "roi_height_m": roi_height,
            "side_features_p50": float(np.median([n for r in rows for n in r["side_features"]]))
            if any(r["side_features"] for r in rows)
            else None,
            "roi_fraction_p50": float(
                np.median([f for r in rows for f, _ in r["side_roi"].values()])
            )
            if roi
            else None,
            "roi_fallbacks": sum(
                1 for r in rows for f, why in r["side_roi"].values() if why.startswith("whole")
            ),
            "rows": rows,
        }
    finally:
        engine.stop()


def main(argv: list[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--json", action="store_true", help="print one JSON object on the last line")
    ap.add_argument("--objects", type=int, default=12, help="trainable entries (1..12)")
    ap.add_argument("--queries", type=int, default=3, help="random yaws per object (1..50)")
    ap.add_argument("--teach-yaws", type=int, default=4, help="object yaws taught (1..12)")
    ap.add_argument("--policy", default="two-views")
    ap.add_argument("--seed", type=int, default=0, help="seed of the query yaws and jitter")
    ap.add_argument("--cache", type=Path, default=None, help="folder caching the rendered images")
    ap.add_argument("--no-baseline", action="store_true", help="skip the rule before the fix")
    ap.add_argument(
        "--no-roi",
        action="store_true",
        help="match side queries over the whole frame (before the side ROI)",
    )
    ap.add_argument(
        "--teach-spread",
        choices=("plan", "half"),
        default="plan",
        help="teach yaws: the teach plan (teach_yaws_rad, the whole turn) or a half turn",
    )
    ap.add_argument(
        "--teach-yaws-deg",
        default=None,
        help="explicit teach yaws, degrees, comma-separated (overrides the spread)",
    )
    args = ap.parse_args(argv)
    yaws_deg = None
    if args.teach_yaws_deg is not None:
        try:
            yaws_deg = [float(v) for v in args.teach_yaws_deg.split(",")]
        except ValueError:
            ap.error(f"--teach-yaws-deg must be numbers, got {args.teach_yaws_deg!r}")
        if not 1 <= len(yaws_deg) <= 12 or not all(
            math.isfinite(y) and abs(y) <= 180 for y in yaws_deg
        ):
            ap.error(f"--teach-yaws-deg: 1..12 yaws within +-180, got {args.teach_yaws_deg!r}")
        args.teach_yaws = len(yaws_deg)
    if not 1 <= args.objects <= 12 or not 1 <= args.queries <= 50 or not 1 <= args.teach_yaws <= 12:
        ap.error("--objects 1..12, --queries 1..50, --teach-yaws 1..12")
    if not 0 <= args.seed < 2**32:
        ap.error(f"--seed must be in 0..2**32-1, got {args.seed}")
    out = run(
        objects=args.objects,
        queries=args.queries,
        teach_yaws=args.teach_yaws,
        policy=args.policy,
        cache=args.cache,
        baseline=not args.no_baseline,
        seed=args.seed,
        roi=not args.no_roi,
        spread=args.teach_spread,
        teach_yaws_deg=yaws_deg,
    )
    table = Table(
        title=f"Recognition at random yaw ({args.policy}): {len(out['rows'])} inspections, "
        f"{out['views']} trained views ({out['teach_yaws']} object yaws)"
    )
    for col in ("thresholds", "top / side 2 / side 3", "trained named %", "untrained unknown %"):
        table.add_column(col)

    def vps(d: dict | None) -> str:
        return "-" if not d else " / ".join(f"{d[k]:.3f}" for k in sorted(d))

    if out["named_pct_before"] is not None:
        table.add_row("twins kept in (before, baseline)", vps(out["threshold_before"]),
                      f"{out['named_pct_before']:.1f}", f"{out['unknown_pct_before']:.1f}")  # fmt: skip
    if out["named_pct_before_smooth_colour"] is not None:
        table.add_row("twins left out, no smoothing, no colour (before, baseline)",
                      vps(out["threshold_before_smooth_colour"]),
                      f"{out['named_pct_before_smooth_colour']:.1f}",
                      f"{out['unknown_pct_before_smooth_colour']:.1f}")  # fmt: skip
    table.add_row(f"now: smoothing {out['options']}, colour tie-break", vps(out["per_viewpoint"]),
                  f"{out['named_pct']:.1f}", f"{out['unknown_pct']:.1f}")  # fmt: skip
    Console().print(table)
    print(f"genuine p10/p50 {out['genuine_p10_p50']}  impostor p50/p99 {out['impostor_p50_p99']}")
    print(
        f"mean views {out['mean_views']:.2f} (teach {out['teach_s']:.0f} s, choose {out['choose_s']:.0f} s)"
    )
    print(f"teach yaws {out['teach_yaws_deg']} deg; side ROI {'on' if out['side_roi'] else 'off'} "
          f"(height bound {out['roi_height_m']:.3f} m, p50 {out['roi_fraction_p50']} of the frame, "
          f"{out['roi_fallbacks']} fallbacks); side query features p50 {out['side_features_p50']}")  # fmt: skip
    for r in out["rows"]:
        if not r["ok"]:
            print(f"  wrong: {r['name']} yaw {r['yaw_deg']} -> {r['decision']} {r['model']} "
                  f"(top {r['own_top']} vs {r['own_top_bar']}, side {r['side']})")  # fmt: skip
    if args.json:
        print(json.dumps(out, default=str))
    return out


if __name__ == "__main__":
    main()
