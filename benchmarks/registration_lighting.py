"""Recognition in the simulated cell under dimmed lights and a colour cast, grey against colour
descriptors side by side (issue 17, part 4; the lighting target of issue 14).

    python -m benchmarks.registration_lighting [--json] [--methods sift color-sift ...]
                                               [--yaws 3] [--seed 0]

One top view per trainable catalogue entry (``robot.sim.catalogue``) is trained at nominal
light into a ``vision.recognition.ViewIndex`` per method; each entry is then seen again at
``--yaws`` random yaws (and a few mm of jitter along the belt) under each condition and
recognised with ``vision.recognition.recognise`` (top viewpoint, default threshold). Trained
views and queries use the simulator's ground-truth silhouette as the segmentation mask.

Conditions: ``nominal``; ``half`` (every lamp and the ambient light at 0.5x, ``set_light``);
``dim`` (0.25x); ``cast`` (nominal light, then a per-channel gain (1.3, 1.0, 0.65) on the
rendered image: the simulator's lamps are white, and MuJoCo renders linear values, so a
warmer lamp is a diagonal gain on the image, clipped at 255); ``half+cast``. The grey methods
are the baseline measured in the same run. A result is correct when the decision is
``recognized`` and names the true model.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from typing import Any

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np
from rich.console import Console
from rich.table import Table

out = Console()
err = Console(stderr=True)
CONDITIONS = ("nominal", "half", "dim", "cast", "half+cast")
CAST_GAIN = np.array([1.3, 1.0, 0.65])
DEFAULT_METHODS = ("sift", "color-sift", "surf", "color-surf")
COLOUR_BASE = {"color-sift": "sift", "color-surf": "surf"}


def _log(msg: str) -> None:
    err.print(f"[dim]{time.strftime('%H:%M:%S')}[/dim] {msg}")


def _cast(rgb: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(rgb * CAST_GAIN), 0, 255).astype(np.uint8)


def render_views(n_yaws: int, seed: int) -> tuple[dict, list[dict[str, Any]]]:
    """Trained views ``{model: (rgb, mask)}`` and queries ``[{model, yaw_deg, condition, rgb,
    mask}]`` rendered by the simulator."""
    from robot.sim import CATALOGUE, SimConfig, SimEngine
    from robot.sim.imaging import capture, object_masks
    from robot.sim.poses import viewpoint

    rng = np.random.default_rng(seed)
    engine = SimEngine(SimConfig())
    conveyor = engine.config.layout.conveyor
    lights = engine.lights()
    models = [n for n, e in CATALOGUE.items() if e.trainable]

    def shot(model: str, yaw_deg: float, shift_m: float, scale: float):
        for name, base in lights.items():
            engine.set_light(name, base * scale)
        engine.clear_objects()
        obj = engine.spawn(model, s_m=conveyor.station_s_m + shift_m, yaw_rad=math.radians(yaw_deg))
        top = float(CATALOGUE[model].geometry().bounds[1, 2])
        q = viewpoint(conveyor.station_point + np.array([0.0, 0.0, top]), "top")
        img = capture(engine, q).rgb
        mask = object_masks(engine)[obj.id]
        return img, mask

    try:
        trained, queries = {}, []
        for k, model in enumerate(models):
            _log(f"rendering {model} ({k + 1}/{len(models)})")
            trained[model] = shot(model, 0.0, 0.0, 1.0)
            for _ in range(n_yaws):
                yaw = float(rng.uniform(0, 360))
                shift = float(rng.uniform(-0.004, 0.004))
                for cond, scale in (("nominal", 1.0), ("half", 0.5), ("dim", 0.25)):
                    img, mask = shot(model, yaw, shift, scale)
                    queries.append(
                        dict(model=model, yaw_deg=yaw, condition=cond, rgb=img, mask=mask)
                    )
                    if cond in ("nominal", "half"):
                        c = "cast" if cond == "nominal" else "half+cast"
                        queries.append(
                            dict(model=model, yaw_deg=yaw, condition=c, rgb=_cast(img), mask=mask)
                        )
        return trained, queries
    finally:
        engine.stop()


def run(methods: list[str], trained: dict, queries: list[dict]) -> list[dict[str, Any]]:
    from vision.recognition import ViewIndex, recognise

    rows = []
    for i, method in enumerate(methods):
        index = ViewIndex(method=method)
        for model, (img, mask) in trained.items():
            index.add(model, img, viewpoint=1, mask=mask)
        for k, q in enumerate(queries):
            if k % 20 == 0:
                _log(f"[{i + 1}/{len(methods)}] {method}: query {k + 1}/{len(queries)}")
            t = time.perf_counter()
            r = recognise(index, q["rgb"], viewpoint=1, mask=q["mask"])
            rows.append(
                {
                    "method": method,
                    "model": q["model"],
                    "condition": q["condition"],
                    "yaw_deg": round(q["yaw_deg"], 1),
                    "decision": r.decision,
                    "named": r.model,
                    "correct": bool(r.decision == "recognized" and r.model == q["model"]),
                    # Ranking, independent of the decision's threshold: the true model has
                    # the highest score of all trained models.
                    "top1": bool(
                        r.scores
                        and max(r.scores, key=r.scores.get) == q["model"]
                        and r.scores[q["model"]] > 0
                    ),
                    "score_true": float(r.scores.get(q["model"], 0.0)),
                    "ms": 1e3 * (time.perf_counter() - t),
                }
            )
    return rows


def summarise(rows: list[dict[str, Any]]) -> dict[str, dict[str, dict[str, float]]]:
    s: dict[str, dict[str, dict[str, float]]] = {}
    for r in rows:
        c = s.setdefault(r["method"], {}).setdefault(
            r["condition"], {"n": 0, "correct": 0.0, "top1": 0.0}
        )
        c["n"] += 1
        c["correct"] += r["correct"]
        c["top1"] += r["top1"]
        c.setdefault("score", []).append(r["score_true"])
        c.setdefault("ms", []).append(r["ms"])
    for conds in s.values():
        for c in conds.values():
            c["accuracy"] = c.pop("correct") / c["n"]
            c["top1"] = c["top1"] / c["n"]
            c["score_true"] = float(np.mean(c.pop("score")))
            c["ms_median"] = float(np.median(c.pop("ms")))
    return s


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true", help="print one JSON object on the last line")
    ap.add_argument("--methods", nargs="+", default=list(DEFAULT_METHODS))
    ap.add_argument("--yaws", type=int, default=3, help="random yaws per model (1..20)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    if not 1 <= args.yaws <= 20:
        ap.error(f"--yaws must be in 1..20, got {args.yaws}")
    from vision.features import METHODS

    bad = [m for m in args.methods if m not in METHODS]
    if bad:
        ap.error(f"unknown methods {bad}; choose from {', '.join(METHODS)}")
    methods = list(dict.fromkeys(args.methods))
    trained, queries = render_views(args.yaws, args.seed)
    rows = run(methods, trained, queries)
    summary = summarise(rows)
    t = Table(
        title=f"Simulated cell, {len(trained)} models x {args.yaws} yaws: correctly recognised % "
        "/ true model scored highest % / mean score of the true model"
    )
    t.add_column("method")
    for c in CONDITIONS:
        t.add_column(c, justify="right")
    t.add_column("ms/query", justify="right")
    for m in methods:
        cs = summary[m]
        t.add_row(
            m,
            *[
                f"{100 * cs[c]['accuracy']:.0f} / {100 * cs[c]['top1']:.0f} / "
                f"{cs[c]['score_true']:.2f}"
                for c in CONDITIONS
            ],
            f"{np.median([cs[c]['ms_median'] for c in CONDITIONS]):.0f}",
        )
    out.print(t)
    if args.json:
        res = {
            "methods": methods,
            "conditions": list(CONDITIONS),
            "cast_gain": CAST_GAIN.tolist(),
            "models": list(trained),
            "summary": summary,
            "rows": rows,
        }
        print(json.dumps(res))
    return 0


if __name__ == "__main__":
    sys.exit(main())
