"""The inspection's top-view region of every catalogue part against the simulator's truth,
with and without the parts the snake cut off added back (the baseline, same images).

For each catalogue entry and each of ``--yaws`` yaws (evenly spread, offset so none is a
symmetry angle): the empty belt and then the part alone at the station are shot from the
``top`` viewpoint 0.55 m above the part's top (:func:`robot.sim.poses.viewpoint`), the
region is :func:`backend.recognition.segment.segment_object` against the empty belt, and
the truth is MuJoCo's segmentation render of the same snapshot with its holes filled (a
region has its holes filled; the belt seen down the flange's tube is not the part, but
neither is it a part the region could leave out).  Reported per part: the mean and worst
overlap (IoU) with the truth, the share of the truth the region missed, and how many views
had parts added back.

    python -m benchmarks.segment_parts [--yaws 4] [--json]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from typing import Any

import numpy as np
from rich.console import Console
from rich.table import Table

out = Console()
err = Console(stderr=True)


def _filled(mask: np.ndarray) -> np.ndarray:
    import cv2

    cs, _ = cv2.findContours(mask.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    f = np.zeros(mask.shape, np.uint8)
    cv2.drawContours(f, cs, -1, 1, -1)
    return f.astype(bool)


def run(yaws: int, parts: tuple[str, ...] = ()) -> dict[str, Any]:
    os.environ.setdefault("MUJOCO_GL", "egl")
    from backend.recognition.segment import segment_object
    from robot.sim.catalogue import CATALOGUE
    from robot.sim.engine import SimEngine
    from robot.sim.imaging import capture, object_masks
    from robot.sim.poses import viewpoint
    from vision.segmentation import iou

    engine = SimEngine()
    belt = engine.config.layout.conveyor
    names = list(parts) if parts else list(CATALOGUE)
    rows: list[dict[str, Any]] = []
    t0 = time.perf_counter()
    try:
        for k, name in enumerate(names):
            entry = CATALOGUE[name]
            err.print(f"[{k + 1}/{len(names)}] {name}")
            h = float(entry.geometry().bounds[1, 2])
            q = viewpoint(belt.station_point + np.array([0.0, 0.0, h]), "top", distance_m=0.55)
            engine.clear_objects()
            bg = capture(engine, q).rgb
            for j in range(yaws):
                yaw = 0.3 + 2 * math.pi * j / yaws
                engine.clear_objects()
                obj = engine.spawn(name, s_m=belt.station_s_m, yaw_rad=yaw)
                shot = capture(engine, q)
                truth = _filled(object_masks(engine, shot.snapshot)[obj.id])
                n = max(1, int(truth.sum()))
                for label, recover in (("snake", False), ("snake + cut-off parts", True)):
                    r = segment_object(shot.rgb, bg, recover_cut=recover)
                    rows.append({
                        "part": name, "yaw_rad": yaw, "method": label,
                        "iou": float(iou(r.mask, truth)),
                        "missed": float((truth & ~r.mask).sum() / n),
                        "extra": float((r.mask & ~truth).sum() / n),
                        "added": "cut-off" in r.method,
                    })  # fmt: skip
    finally:
        engine.stop()
    summary = []
    for name in names:
        for label in ("snake", "snake + cut-off parts"):
            rs = [r for r in rows if r["part"] == name and r["method"] == label]
            summary.append({
                "part": name, "method": label, "views": len(rs),
                "iou_mean": float(np.mean([r["iou"] for r in rs])),
                "iou_min": float(np.min([r["iou"] for r in rs])),
                "missed_mean": float(np.mean([r["missed"] for r in rs])),
                "extra_mean": float(np.mean([r["extra"] for r in rs])),
                "added": sum(r["added"] for r in rs),
            })  # fmt: skip
    return {"summary": summary, "rows": rows, "wall_s": time.perf_counter() - t0}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--yaws", type=int, default=4, help="yaws per part (1..36)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    if not 1 <= args.yaws <= 36:
        ap.error(f"--yaws must be in 1..36, got {args.yaws}")
    res = run(args.yaws)
    table = Table(title=f"Top-view region against the truth ({args.yaws} yaws per part)")
    for col in ("part", "method", "IoU mean", "IoU min", "missed %", "extra %", "added"):
        table.add_column(col)
    for s in res["summary"]:
        table.add_row(
            s["part"], s["method"], f"{s['iou_mean']:.3f}", f"{s['iou_min']:.3f}",
            f"{100 * s['missed_mean']:.1f}", f"{100 * s['extra_mean']:.1f}",
            f"{s['added']}/{s['views']}",
        )  # fmt: skip
    out.print(table)
    if args.json:
        sys.stdout.write(json.dumps({k: v for k, v in res.items() if k != "rows"}) + "\n")


if __name__ == "__main__":
    main()
