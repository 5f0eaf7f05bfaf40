"""The top view's verification budget (issue 14): a model's views verified by votes alone
against as many of its voted views as fit the budget (:data:`VERIFY_FEATURES`).

    python -m benchmarks.recognition_budget [--json] [--queries 8] [--teach-yaws 8]
        [--offset-mm 20] [--seed 0] [--cache DIR]

Procedure (simulated cell, no database): every trainable catalogue entry is taught from the
top as the teach job teaches it (:func:`backend.recognition.teach.plan_shots`, viewpoint 1 at
the camera rolls of ``TOP_ROLLS_RAD``, at ``--teach-yaws`` object yaws spread by
:func:`backend.recognition.teach.teach_yaws_rad`, segmented by the active contour from the
empty belt). Each entry, and each untrained one, is then put on the belt ``--queries`` times
at a random yaw, up to ``--offset-mm`` along the belt from the station (at constant belt
speed the top view is taken of an object up to about 20 mm from it) and 4 mm across, and
its top view is recognised with each rule, on the same images in the same run:

* ``budget``: this build (:func:`vision.recognition.recognise` as it stands);
* ``by votes``: the rule before, ``VERIFY_FEATURES = 0`` (each model's two best-voted views).

Each rule chooses its own thresholds from the same views (:func:`choose_threshold`, as
after a teach). Printed per rule (rich table; ``--json`` one line): the own model's top
score (p10, median), the share named from the top alone, the share left under the shortlist
bar (the top view sends such an object nowhere: ``unknown`` after one view, the valve block's
miss in ``benchmarks.inspection``), untrained objects named, views verified per query and
the verification time (median, p95); then the same per model for the plain parts. Rendering
is the slow part: ``--cache DIR`` keeps the images for a rerun.
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import importlib
import json
import math
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console
from rich.table import Table

from benchmarks.recognition_yaw import _cached, _log, render_query, render_teach

RULES = ("budget", "by votes")


@contextlib.contextmanager
def _rule(name: str) -> Iterator[None]:
    """The verification rule ``name`` in force (the module's budget, or none)."""
    rec = importlib.import_module("vision.recognition.recognise")
    kept = rec.VERIFY_FEATURES
    if name == "by votes":
        rec.VERIFY_FEATURES = 0
    try:
        yield
    finally:
        rec.VERIFY_FEATURES = kept


def _counting(verify: Callable[..., Any], calls: list[int]) -> Callable[..., Any]:
    """``verify``, counting its calls in ``calls``."""

    def counted(*a: Any, **k: Any) -> Any:
        calls.append(1)
        return verify(*a, **k)

    return counted


def run(
    *,
    queries: int = 8,
    teach_yaws: int = 8,
    offset_mm: float = 20.0,
    seed: int = 0,
    cache: Path | None = None,
    names: list[str] | None = None,
    untrained: list[str] | None = None,
) -> dict[str, Any]:
    """Teach the top views, choose the thresholds and recognise (module docstring);
    ``names`` and ``untrained`` replace the catalogue's trainable and untrained entries."""
    from backend.hardware import headless_mujoco

    headless_mujoco()
    from backend.calibration.autoplan import NOMINAL_T_EE_CAM
    from backend.planning import plan_shots
    from backend.recognition.index import FEATURE_OPTIONS
    from backend.recognition.teach import TOP_ROLLS_RAD, teach_yaws_rad
    from robot.sim import CATALOGUE, SimEngine
    from robot.sim.imaging import capture
    from vision.recognition import ViewIndex, choose_threshold, recognise

    rec = importlib.import_module("vision.recognition.recognise")
    real_verify = rec.verify_view
    rng = np.random.default_rng(seed)
    engine = SimEngine()
    try:
        belt = engine.config.layout.conveyor
        if names is None:
            names = [n for n, e in CATALOGUE.items() if e.trainable]
        if untrained is None:
            untrained = [n for n, e in CATALOGUE.items() if not e.trainable]
        point = np.asarray(belt.station_point, dtype=np.float64)
        shots = plan_shots(
            point, (1,), T_ee_cam=np.asarray(NOMINAL_T_EE_CAM), object_height_m=0.1,
            top_rolls_rad=TOP_ROLLS_RAD,
        )  # fmt: skip

        def empty() -> dict[Any, Any]:
            engine.clear_objects()
            return {s.key: capture(engine, s.q).rgb for s in shots}

        backgrounds = _cached(cache, "budget-backgrounds", empty)
        index = ViewIndex("sift", feature_options=dict(FEATURE_OPTIONS.get("sift", {})))
        for k, name in enumerate(names):
            _log(f"  teaching {k + 1}/{len(names)}: {name}")
            for yaw in teach_yaws_rad(teach_yaws):
                render = functools.partial(render_teach, engine, name, yaw, shots, backgrounds)
                key = f"budget-teach-{name}-{math.degrees(yaw):.1f}"
                for (rgb, mask), s in zip(_cached(cache, key, render), shots, strict=True):
                    index.add(name, rgb, viewpoint=s.viewpoint, mask=mask.astype(np.uint8))
        top = shots[0]  # the inspection's top view: the first roll
        probes: list[tuple[str, bool, Any]] = []
        for name, trainable in [(n, True) for n in names] + [(n, False) for n in untrained]:
            for _ in range(queries):
                yaw = float(rng.uniform(-math.pi, math.pi))
                ds = float(rng.uniform(-offset_mm, offset_mm)) * 1e-3
                dl = float(rng.uniform(-0.004, 0.004))

                def shoot(
                    name: str = name, yaw: float = yaw, ds: float = ds, dl: float = dl
                ) -> Any:
                    rgb, region = render_query(engine, name, yaw, ds, dl, top, backgrounds)
                    return rgb, region.mask

                key = f"budget-query-{name}-{yaw:.6f}-{ds:.6f}-{dl:.6f}"
                rgb, mask = _cached(cache, key, shoot)
                probes.append((name, trainable, index.features(rgb, mask=mask.astype(np.uint8))))
        _log(f"  {len(index)} top views taught, {len(probes)} queries rendered")

        out: dict[str, Any] = {"views": len(index), "queries": len(probes), "rules": {}}
        for rule in RULES:
            with _rule(rule):
                t0 = time.perf_counter()
                choice = choose_threshold(index)
                choose_s = time.perf_counter() - t0
                at1 = choice.at(1)
                rows = []
                calls: list[int] = []
                rec.verify_view = _counting(real_verify, calls)
                try:
                    for name, trainable, feats in probes:
                        calls.clear()
                        r = recognise(index, feats, viewpoint=1, threshold=choice)
                        own = float(r.scores.get(name, 0.0)) if trainable else 0.0
                        shortlist = min(at1.candidate, choice.own(name, 1)) if trainable else None
                        rows.append({
                            "name": name, "trainable": trainable, "own": own,
                            "named_top": r.decision == "recognized" and r.model == name,
                            "named_any": r.decision == "recognized",
                            "under_shortlist": trainable and own <= shortlist,
                            "verified": len(calls), "verify_ms": 1e3 * r.verification_s,
                        })  # fmt: skip
                finally:
                    rec.verify_view = real_verify
            tr = [r for r in rows if r["trainable"]]
            un = [r for r in rows if not r["trainable"]]
            per_model = {
                n: {
                    "own_min": min(r["own"] for r in tr if r["name"] == n),
                    "own_p50": float(np.median([r["own"] for r in tr if r["name"] == n])),
                    "bar": float(choice.own(n, 1)),
                }
                for n in names
            }
            out["rules"][rule] = {
                "top_bar": float(at1.threshold),
                "choose_s": choose_s,
                "own_p10": float(np.percentile([r["own"] for r in tr], 10)),
                "own_p50": float(np.median([r["own"] for r in tr])),
                "named_top_pct": 100.0 * np.mean([r["named_top"] for r in tr]),
                "under_shortlist_pct": 100.0 * np.mean([r["under_shortlist"] for r in tr]),
                "untrained_named_pct": 100.0 * np.mean([r["named_any"] for r in un])
                if un
                else None,
                "verified_mean": float(np.mean([r["verified"] for r in rows])),
                "verify_ms_p50": float(np.median([r["verify_ms"] for r in rows])),
                "verify_ms_p95": float(np.percentile([r["verify_ms"] for r in rows], 95)),
                "per_model": per_model,
                "rows": rows,
            }
            _log(f"  {rule}: {out['rules'][rule]['named_top_pct']:.1f} % named from the top")
        return out
    finally:
        engine.stop()


def main(argv: list[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--queries", type=int, default=8, help="queries per catalogue entry")
    ap.add_argument("--teach-yaws", type=int, default=8)
    ap.add_argument("--offset-mm", type=float, default=20.0, help="along the belt, +/-")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--cache", type=Path, default=None)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    for flag, value, lo, hi in (("--queries", args.queries, 1, 200),
                                ("--teach-yaws", args.teach_yaws, 1, 24)):  # fmt: skip
        if not lo <= value <= hi:
            ap.error(f"{flag} must be within {lo}..{hi}, got {value}")
    if not (math.isfinite(args.offset_mm) and 0.0 <= args.offset_mm <= 40.0):
        ap.error(f"--offset-mm must be within 0..40, got {args.offset_mm}")
    t0 = time.perf_counter()
    out = run(queries=args.queries, teach_yaws=args.teach_yaws, offset_mm=args.offset_mm,
              seed=args.seed, cache=args.cache)  # fmt: skip
    out["wall_s"] = time.perf_counter() - t0
    if args.json:
        print(json.dumps(out))
        return out
    table = Table(title=f"Top-view verification budget ({out['queries']} queries, "
                        f"{out['views']} taught top views)")  # fmt: skip
    table.add_column("")
    for rule in RULES:
        table.add_column(rule, justify="right")
    rules = out["rules"]
    for label, key, fmt in (
        ("top bar", "top_bar", "{:.3f}"),
        ("own top score p10", "own_p10", "{:.3f}"),
        ("own top score median", "own_p50", "{:.3f}"),
        ("named from the top, %", "named_top_pct", "{:.1f}"),
        ("under the shortlist bar, %", "under_shortlist_pct", "{:.1f}"),
        ("untrained named, %", "untrained_named_pct", "{:.1f}"),
        ("views verified per query", "verified_mean", "{:.1f}"),
        ("verification ms, median", "verify_ms_p50", "{:.1f}"),
        ("verification ms, p95", "verify_ms_p95", "{:.1f}"),
        ("threshold choice, s", "choose_s", "{:.1f}"),
    ):
        table.add_row(label, *(fmt.format(rules[r][key]) if rules[r][key] is not None else "-"
                               for r in RULES))  # fmt: skip
    for name in rules[RULES[0]]["per_model"]:
        table.add_row(f"{name}: own min / median (bar)", *(
            "{own_min:.2f} / {own_p50:.2f} ({bar:.2f})".format(**rules[r]["per_model"][name])
            for r in RULES
        ))  # fmt: skip
    Console(file=sys.stdout).print(table)
    return out


if __name__ == "__main__":
    main()
