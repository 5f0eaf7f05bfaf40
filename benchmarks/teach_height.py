"""How well the teach measures a part's height (features, else silhouettes), against the simulator.

    python -m benchmarks.teach_height [--json] [--objects 12] [--yaws 2]

Procedure (simulated cell, rendered afresh, nothing stored): the teach's shots are planned
at the station by :func:`backend.recognition.teach.plan_shots` (the top view at its three
rolls and the two side views), their empty-belt backgrounds grabbed, then each trainable
catalogue entry lies at the station at ``--yaws`` yaws (evenly spread), is seen from those
shots, segmented by the active contour from the backgrounds and its features extracted
inside the region (as the teach does), and measured as the teach measures it (the top
views' triangulated features, else the silhouettes: :mod:`backend.recognition.geometry`).  The error is taken against the
catalogue's height (the top of its mesh's bounding box): that truth is read here only, for
the comparison, never by the product.  The baseline is what a model without a measured
height assumes (the tallest object the station admits, 0.25 m, and the search descent it
implies).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import time
from typing import Any

import numpy as np

from backend.inspection.sort import MEASURED_MARGIN_M

#: What the cell assumes of an object whose height it does not know, metres.
BASELINE_M = 0.25


def run(*, objects: int = 12, yaws: int = 2) -> dict[str, Any]:
    from backend.hardware import headless_mujoco

    headless_mujoco()
    from backend.calibration.autoplan import NOMINAL_T_EE_CAM
    from backend.planning import plan_shots
    from backend.recognition import teachheight
    from backend.recognition.geometry import Silhouette, TopShot
    from backend.recognition.index import FEATURE_OPTIONS
    from backend.recognition.segment import segment_object
    from backend.recognition.teach import TOP_ROLLS_RAD
    from robot.kinematics import T_base_ee
    from robot.sim import CATALOGUE, SimEngine
    from robot.sim.imaging import capture
    from vision.recognition import ViewIndex

    engine = SimEngine()
    try:
        belt = engine.config.layout.conveyor
        camera = engine.config.camera.pinhole
        T_ee_cam = np.asarray(engine.config.camera.T_ee_cam, dtype=np.float64)
        names = [n for n, e in CATALOGUE.items() if e.trainable][:objects]
        point = np.asarray(belt.station_point, dtype=np.float64)
        shots = plan_shots(point, (1, 2, 3), T_ee_cam=NOMINAL_T_EE_CAM, object_height_m=0.1,
                           top_rolls_rad=TOP_ROLLS_RAD)  # fmt: skip
        index = ViewIndex("sift", feature_options=FEATURE_OPTIONS.get("sift", {}))
        engine.clear_objects()
        backgrounds = {s.key: capture(engine, s.q).rgb for s in shots}
        rows = []
        t0 = time.perf_counter()
        for k, name in enumerate(names):
            truth = float(CATALOGUE[name].geometry().bounds[1, 2])
            for j in range(yaws):
                yaw = math.remainder(2.0 * math.pi * j / yaws + 0.3, 2.0 * math.pi)
                print(f"  {k + 1}/{len(names)} {name} at {math.degrees(yaw):.0f} deg", flush=True)
                engine.clear_objects()
                engine.spawn(name, s_m=belt.station_s_m, yaw_rad=yaw)
                sils, tops = [], []
                for s in shots:
                    rgb = capture(engine, s.q).rgb
                    region = segment_object(rgb, backgrounds[s.key])
                    # the camera's mounting as the product takes it in the simulator
                    # (no hand-eye calibration: the simulator's nominal mounting)
                    T = T_base_ee(s.q) @ T_ee_cam
                    sils.append((s, Silhouette(region.mask, T)))
                    if s.viewpoint == 1:
                        feats = index.features(rgb, mask=region.mask.astype(np.uint8))
                        tops.append(TopShot(feats, T))
                got = asyncio.run(
                    teachheight.measure(sils, tops, camera, (640, 480), float(point[2]))
                )
                rows.append({
                    "name": name, "yaw_deg": round(math.degrees(yaw), 1),
                    "truth_mm": round(truth * 1e3, 1),
                    "measured_mm": None if got.height_m is None else round(got.height_m * 1e3, 1),
                    "error_mm": None if got.height_m is None
                    else round((got.height_m - truth) * 1e3, 1),
                    "per_view_mm": [round(v * 1e3, 1) for v in got.per_view_m],
                    "method": got.method, "note": got.note,
                })  # fmt: skip
        errs = np.array([abs(r["error_mm"]) for r in rows if r["error_mm"] is not None])
        base = np.array([abs(BASELINE_M * 1e3 - r["truth_mm"]) for r in rows])
        by_features = [r for r in rows if r["method"] == "features" and r["error_mm"] is not None]
        return {
            "measurements": len(rows),
            "measured": len(errs),
            "abs_error_mm_median": round(float(np.median(errs)), 1) if len(errs) else None,
            "abs_error_mm_p90": round(float(np.percentile(errs, 90)), 1) if len(errs) else None,
            "abs_error_mm_max": round(float(errs.max()), 1) if len(errs) else None,
            "baseline_abs_error_mm_median": round(float(np.median(base)), 1),
            "from_features": len(by_features),
            "from_features_within_5mm": sum(abs(r["error_mm"]) <= 5.0 for r in by_features),
            "under_by_more_than_margin": sum(
                r["error_mm"] is not None and r["error_mm"] < -MEASURED_MARGIN_M * 1e3 for r in rows
            ),
            "rows": rows,
            "seconds": round(time.perf_counter() - t0, 1),
        }
    finally:
        engine.stop()


def main(argv: list[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--json", action="store_true", help="print one JSON object on the last line")
    ap.add_argument("--objects", type=int, default=12, help="trainable entries used (1..12)")
    ap.add_argument("--yaws", type=int, default=2, help="yaws per object (1..8)")
    args = ap.parse_args(argv)
    if not 1 <= args.objects <= 12 or not 1 <= args.yaws <= 8:
        ap.error(f"--objects must be in 1..12 and --yaws in 1..8, got {args.objects}, {args.yaws}")
    out = run(objects=args.objects, yaws=args.yaws)
    print(
        f"\nHeight measured at teach (features, else silhouettes), {out['measurements']} placements"
    )
    print(f"{'part':24s} {'yaw':>6s} {'truth mm':>9s} {'measured':>9s} {'error':>7s}  method")
    for r in out["rows"]:
        m = "-" if r["measured_mm"] is None else f"{r['measured_mm']:.1f}"
        e = "-" if r["error_mm"] is None else f"{r['error_mm']:+.1f}"
        print(f"{r['name']:24s} {r['yaw_deg']:6.0f} {r['truth_mm']:9.1f} {m:>9s} {e:>7s}  "
              f"{r['method']}: {r['note']}")  # fmt: skip
    print(f"measured {out['measured']}/{out['measurements']}; |error| median "
          f"{out['abs_error_mm_median']} mm, p90 {out['abs_error_mm_p90']} mm, max "
          f"{out['abs_error_mm_max']} mm; baseline (assume {BASELINE_M * 1e3:.0f} mm) median "
          f"{out['baseline_abs_error_mm_median']} mm; from the features "
          f"{out['from_features']}, of them within 5 mm {out['from_features_within_5mm']}; "
          f"under the truth by more than the pick's {MEASURED_MARGIN_M * 1e3:.0f} mm margin: "
          f"{out['under_by_more_than_margin']}")  # fmt: skip
    if args.json:
        print(json.dumps(out))
    return out


if __name__ == "__main__":
    main()
