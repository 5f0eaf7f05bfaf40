"""Top-view score against the part's yaw on the belt, stage by stage (issue 14).

    python -m benchmarks.recognition_yaw_curve [--json] [--parts gear-housing,valve-block]
        [--yaws 0,15,30,45,60,90]

Procedure (simulated cell, no database): each part is put at the station at yaw 0 and its
top view (camera roll 0, planned with the drawing's mounting as an uncalibrated cell does)
is taught into a one-view index, segmented from the empty belt as the teach job does. It is
then put back at each yaw and seen from the same pose through a camera with fresh sensor
noise (another noise seed: a new frame, not a copy of the taught one). Each query is matched
against the taught view (``vision.registration.match`` with the recognition's ratio and
mutual check), verified (``verify``, the index's affine model) and scored
(``registration_score``); printed per yaw: query features, tentative matches, inliers and
the score. As a control in the same run, the taught image itself turned in the image plane
(``numpy.rot90``, an exact rotation: 0 / 90 / 180 deg) shows what the features do when the
render is not involved.

Rows: ``before`` = the extraction options without issue 14's ``smooth_px`` (the baseline),
``now`` = ``backend.recognition.index.FEATURE_OPTIONS``. Medians over the turned yaws
(every yaw but 0) are the figures quoted in the README.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
from typing import Any

import numpy as np
from rich.console import Console
from rich.table import Table

DEFAULT_PARTS = ("gear-housing", "valve-block", "pipe-flange", "bracket-upright", "wheel-steel")
DEFAULT_YAWS = (0, 15, 30, 45, 60, 90)


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def _render(parts: tuple[str, ...], yaws: tuple[int, ...]) -> dict[str, Any]:
    """Taught (yaw 0, noise seed 0) and query (every yaw, noise seed 1) images with masks."""
    from backend.hardware import headless_mujoco

    headless_mujoco()
    from backend.calibration.autoplan import NOMINAL_T_EE_CAM
    from backend.planning import plan_shots
    from backend.recognition.segment import segment_object
    from robot.sim import SimEngine
    from robot.sim.imaging import capture

    engine = SimEngine()
    try:
        belt = engine.config.layout.conveyor
        point = np.asarray(belt.station_point, dtype=np.float64)
        shot = plan_shots(point, (1,), T_ee_cam=np.asarray(NOMINAL_T_EE_CAM),
                          object_height_m=0.1, top_rolls_rad=(0.0,))[0]  # fmt: skip
        taught_cam = engine.config.camera
        query_cam = dataclasses.replace(taught_cam, seed=taught_cam.seed + 1)
        engine.clear_objects()
        bg = {
            k: capture(engine, shot.q, spec=s).rgb for k, s in (("t", taught_cam), ("q", query_cam))
        }
        out: dict[str, Any] = {}
        for name in parts:
            _log(f"  rendering {name}")
            for yaw in yaws:
                engine.clear_objects()
                engine.spawn(name, s_m=belt.station_s_m, yaw_rad=math.radians(yaw))
                if yaw == 0:
                    rgb = capture(engine, shot.q, spec=taught_cam).rgb
                    out[(name, "taught")] = (rgb, segment_object(rgb, bg["t"]).mask)
                rgb = capture(engine, shot.q, spec=query_cam).rgb
                out[(name, yaw)] = (rgb, segment_object(rgb, bg["q"]).mask)
        return out
    finally:
        engine.stop()


def _stage(index: Any, taught: Any, image: np.ndarray, mask: np.ndarray) -> dict[str, Any]:
    from vision.recognition.recognise import DEFAULT_RATIO, REPROJ_PX
    from vision.registration import match, registration_score, verify

    q = index.features(image, mask=mask.astype(np.uint8))
    m = match(taught, q, ratio=DEFAULT_RATIO, mutual=True, method="exact")
    ver = verify(m, taught, q, model=index.geometry, reproj_px=REPROJ_PX)
    score = registration_score(ver, m, taught)[0]
    return {"features": len(q), "matches": len(m), "inliers": ver.n_inliers,
            "score": round(float(score), 3)}  # fmt: skip


def run(
    parts: tuple[str, ...] = DEFAULT_PARTS, yaws: tuple[int, ...] = DEFAULT_YAWS
) -> dict[str, Any]:
    """Render, then score every yaw for both extraction settings (module docstring)."""
    from backend.recognition.index import FEATURE_OPTIONS
    from vision.recognition import ViewIndex

    images = _render(parts, yaws)
    now = dict(FEATURE_OPTIONS.get("sift", {}))
    before = {k: v for k, v in now.items() if k != "smooth_px"}
    rows: list[dict[str, Any]] = []
    for name in parts:
        rgb0, m0 = images[(name, "taught")]
        for label, options in (("before", before), ("now", now)):
            index = ViewIndex("sift", feature_options=options)
            index.add(name, rgb0, viewpoint=1, mask=m0.astype(np.uint8))
            taught = index.views[0].features
            per_yaw = {y: _stage(index, taught, *images[(name, y)]) for y in yaws}
            turn = np.ascontiguousarray
            control = {
                90 * k: _stage(index, taught, turn(np.rot90(rgb0, k)), turn(np.rot90(m0, k)))
                for k in (1, 2)
            }
            turned = [per_yaw[y]["score"] for y in yaws if y != 0]
            rows.append({"part": name, "options": label, "taught_features": len(taught),
                         "yaws": per_yaw, "rot90_control": control,
                         "median_turned": float(np.median(turned)) if turned else None})  # fmt: skip
    med = {
        label: float(np.median([r["median_turned"] for r in rows if r["options"] == label]))
        for label in ("before", "now")
    }
    return {"parts": list(parts), "yaws": list(yaws), "options_now": now, "rows": rows,
            "median_of_medians": med}  # fmt: skip


def main(argv: list[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--json", action="store_true", help="print one JSON object on the last line")
    ap.add_argument(
        "--parts", default=",".join(DEFAULT_PARTS), help="catalogue names, comma-separated"
    )
    ap.add_argument(
        "--yaws", default=",".join(map(str, DEFAULT_YAWS)), help="degrees, comma-separated"
    )
    args = ap.parse_args(argv)
    parts = tuple(p for p in args.parts.split(",") if p)
    try:
        yaws = tuple(int(y) for y in args.yaws.split(",") if y)
    except ValueError:
        ap.error(f"--yaws must be integers in degrees, got {args.yaws!r}")
    if not 1 <= len(parts) <= 12 or not 1 <= len(yaws) <= 24 or any(abs(y) > 180 for y in yaws):
        ap.error("--parts 1..12 names, --yaws 1..24 angles within +-180 deg")
    out = run(parts, yaws)
    table = Table(title="Top-view score vs yaw (taught at 0; score (inliers/matches/features))")
    table.add_column("part")
    table.add_column("options")
    for y in yaws:
        table.add_column(f"{y} deg")
    table.add_column("rot90 / 180 control")
    table.add_column("median turned")
    for r in out["rows"]:
        cells = [f"{s['score']:.2f} ({s['inliers']}/{s['matches']}/{s['features']})"
                 for s in r["yaws"].values()]  # fmt: skip
        ctrl = " / ".join(f"{s['score']:.2f}" for s in r["rot90_control"].values())
        table.add_row(r["part"], r["options"], *cells, ctrl, f"{r['median_turned']:.2f}")
    Console(width=200).print(table)
    med = out["median_of_medians"]
    print(f"median over parts of the median turned score: before {med['before']:.3f}, "
          f"now {med['now']:.3f} (options now {out['options_now']})")  # fmt: skip
    if args.json:
        print(json.dumps(out, default=str))
    return out


if __name__ == "__main__":
    main()
