"""How many camera rolls the top view of a teach needs so a model is recognised at any yaw.

    python -m benchmarks.teach_yaw [--json] [--queries 4] [--objects 12]

Procedure (simulated cell, rendered afresh, nothing stored): for each trainable catalogue
entry, the object lies at the station at yaw 0 and is taught from the top view planned by
:func:`backend.recognition.teach.plan_shots` (segmented by the active contour from the
empty-belt background, features inside the mask) with each roll set below; then the same
object is put back at ``--queries`` random yaws (seeded) and a few mm of jitter, seen from
the top at roll 0, segmented the same way and recognised (:func:`vision.recognition.
recognise`, top view, default threshold) against the index of that roll set (SIFT with the
live index's options, ``backend.recognition.index.FEATURE_OPTIONS``).  A query
counts correct when the best-scoring model is the object's own, or its top-view twin
(``wheel-5spoke`` and ``wheel-5spoke-redband`` are identical from the top).  The baseline is
the single view at roll 0 (the chapter's one trained image per viewpoint).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from typing import Any

import numpy as np

TWINS = {"wheel-5spoke": "wheel-5spoke-redband", "wheel-5spoke-redband": "wheel-5spoke"}
ROLL_SETS: dict[str, tuple[float, ...]] = {
    "1 roll (baseline)": (0.0,),
    "2 rolls (0, 180)": (0.0, math.radians(165.0)),
    "3 rolls (0, +-120)": (0.0, math.radians(120.0), math.radians(-120.0)),
    "4 rolls (0, +-90, 165)": (0.0, math.radians(90.0), math.radians(-90.0), math.radians(165.0)),
}


def run(*, queries: int = 4, objects: int = 12, seed: int = 0) -> dict[str, Any]:
    from backend.hardware import headless_mujoco

    headless_mujoco()
    from backend.calibration.autoplan import NOMINAL_T_EE_CAM
    from backend.planning import plan_shots
    from backend.recognition.index import FEATURE_OPTIONS
    from backend.recognition.segment import segment_object
    from robot.sim import CATALOGUE, SimEngine
    from robot.sim.imaging import capture
    from vision.recognition import ViewIndex, recognise

    rng = np.random.default_rng(seed)
    engine = SimEngine()
    try:
        belt = engine.config.layout.conveyor
        names = [n for n, e in CATALOGUE.items() if e.trainable][:objects]
        point = np.asarray(belt.station_point, dtype=np.float64)
        shots = {
            label: plan_shots(
                point, (1,), T_ee_cam=NOMINAL_T_EE_CAM, object_height_m=0.1, top_rolls_rad=rolls
            )
            for label, rolls in ROLL_SETS.items()
        }
        engine.clear_objects()
        backgrounds = {}
        for ss in shots.values():
            for s in ss:
                backgrounds[s.key] = capture(engine, s.q).rgb
        options = FEATURE_OPTIONS.get("sift", {})
        indexes = {label: ViewIndex("sift", feature_options=options) for label in ROLL_SETS}
        snake_used: dict[str, int] = {}
        t0 = time.perf_counter()
        for k, name in enumerate(names):
            print(f"  teaching {k + 1}/{len(names)}: {name}", flush=True)
            engine.clear_objects()
            engine.spawn(name, s_m=belt.station_s_m, yaw_rad=0.0)
            for label, ss in shots.items():
                for s in ss:
                    rgb = capture(engine, s.q).rgb
                    region = segment_object(rgb, backgrounds[s.key])
                    snake_used[region.method] = snake_used.get(region.method, 0) + 1
                    mask = region.mask
                    indexes[label].add(name, rgb, viewpoint=1, mask=mask.astype(np.uint8))
        q_top = shots["1 roll (baseline)"][0]
        hits = {label: 0 for label in ROLL_SETS}
        misses: dict[str, dict[str, int]] = {label: {} for label in ROLL_SETS}
        own_scores: dict[str, list[float]] = {label: [] for label in ROLL_SETS}
        total = 0
        for k, name in enumerate(names):
            print(f"  querying {k + 1}/{len(names)}: {name}", flush=True)
            for _ in range(queries):
                engine.clear_objects()
                yaw = float(rng.uniform(-math.pi, math.pi))
                ds = float(rng.uniform(-0.004, 0.004))
                engine.spawn(name, s_m=belt.station_s_m + ds, yaw_rad=yaw)
                rgb = capture(engine, q_top.q).rgb
                region = segment_object(rgb, backgrounds[q_top.key])
                snake_used[region.method] = snake_used.get(region.method, 0) + 1
                mask = region.mask
                total += 1
                for label, index in indexes.items():
                    r = recognise(index, rgb, viewpoint=1, mask=mask.astype(np.uint8))
                    if r.best_model in (name, TWINS.get(name)):
                        hits[label] += 1
                    else:
                        misses[label][name] = misses[label].get(name, 0) + 1
                    own_scores[label].append(float(r.scores.get(name, 0.0)))
        rows = [
            {
                "rolls": label,
                "views": len(ROLL_SETS[label]) * len(names),
                "correct_pct": round(100.0 * hits[label] / max(total, 1), 1),
                "own_score_median": round(float(np.median(own_scores[label])), 3),
                "own_score_p10": round(float(np.percentile(own_scores[label], 10)), 3),
                "misses": misses[label],
            }
            for label in ROLL_SETS
        ]
        return {
            "queries": total,
            "objects": len(names),
            "rows": rows,
            "segmentation": snake_used,
            "seconds": time.perf_counter() - t0,
        }
    finally:
        engine.stop()


def main(argv: list[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--json", action="store_true", help="print one JSON object on the last line")
    ap.add_argument("--queries", type=int, default=4, help="random yaws per object (1..50)")
    ap.add_argument("--objects", type=int, default=12, help="trainable entries used (1..12)")
    args = ap.parse_args(argv)
    if not 1 <= args.queries <= 50 or not 1 <= args.objects <= 12:
        ap.error(
            f"--queries must be in 1..50 and --objects in 1..12, got {args.queries}, {args.objects}"
        )
    out = run(queries=args.queries, objects=args.objects)
    print(
        f"\nTop-view recognition at random yaw, {out['queries']} queries of {out['objects']} objects"
    )
    print(
        f"{'top-view rolls taught':26s} {'views':>6s} {'correct %':>10s} {'own score p50':>14s} {'p10':>6s}"
    )
    for r in out["rows"]:
        print(
            f"{r['rolls']:26s} {r['views']:6d} {r['correct_pct']:10.1f} "
            f"{r['own_score_median']:14.3f} {r['own_score_p10']:6.3f}"
        )
    for r in out["rows"]:
        print(f"  misses with {r['rolls']}: {r['misses'] or 'none'}")
    print(f"segmentation of the {sum(out['segmentation'].values())} images: {out['segmentation']}")
    if args.json:
        print(json.dumps(out))
    return out


if __name__ == "__main__":
    main()
