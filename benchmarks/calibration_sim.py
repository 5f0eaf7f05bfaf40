"""Automatic calibration in the simulated cell, judged against the simulator's ground truth.

Each run plans views of the board on the table, moves the simulated arm (driver at 8x real
time), grabs, detects and solves intrinsics and hand-eye in-process
(:func:`backend.calibration.simrun.run_sim_auto`), then compares with ``engine.truth``.
The baseline, measured in the same process, is the model the run starts from: the
nominal lens (60 deg vertical field of view, no distortion) and the drawing's mounting.

Run on its own with ``python -m benchmarks.calibration_sim [--json] [--seeds 0,1,2]``, or as
the sim section of ``python -m benchmarks.calibration``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from typing import Any

from rich.console import Console
from rich.progress import Progress
from rich.table import Table

out = Console(soft_wrap=True, width=150)
err = Console(stderr=True, soft_wrap=True)

TARGETS = "targets: fx, fy <= 0.2 %, principal point <= 1 px, map <= 0.3 px, 1 mm, 0.1 deg"


def nominal_baseline() -> dict[str, float]:
    """Errors of the planning model (before any calibration) against the simulator's truth."""
    from backend.calibration.auto import nominal_camera
    from backend.calibration.autoplan import NOMINAL_T_EE_CAM
    from backend.calibration.simrun import _judge
    from robot.sim import SimConfig
    from robot.sim.truth import CameraTruth

    truth = CameraTruth.from_spec(SimConfig().camera)
    cam = nominal_camera(truth.width, truth.height)
    return _judge(
        {"K": cam.K.tolist(), "dist": [0.0] * 5, "T_ee_cam": NOMINAL_T_EE_CAM.tolist()}, truth
    )


def bench_sim(
    seeds: list[int], boards: list[str], progress: Progress, *, n_poses: int = 25
) -> dict[str, Any]:
    """One auto run per (board, seed); rows of errors against the truth."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    from backend.calibration.simrun import run_sim_auto

    rows = []
    for board in boards:
        for seed in seeds:
            task = progress.add_task(f"auto {board} seed {seed}", total=1.0)

            def update(f: float, msg: str, task: Any = task) -> None:
                progress.update(task, completed=f)

            rep = run_sim_auto(board=board, n_poses=n_poses, seed=seed, progress=update)
            progress.remove_task(task)
            r = rep.result
            rows.append(
                {
                    "board": board,
                    "seed": seed,
                    **{k: v for k, v in rep.as_dict().items() if k != "result"},
                    "views": r["views"],
                    "accepted": r["accepted"],
                    "coverage": r["coverage"],
                    "rms_px": r["rms_px"],
                }
            )
    return {"rows": rows, "baseline": nominal_baseline(), "n_poses": n_poses}


def print_sim(sim: dict[str, Any]) -> None:
    """The sim section's table."""
    t = Table(
        title=f"simulated cell, automatic calibration with {sim['n_poses']} planned poses vs "
        f"ground truth ({TARGETS})"
    )
    for col in (
        "run",
        "views (board)",
        "fx err %",
        "fy err %",
        "pp err px",
        "map err px",
        "T_ee_cam mm",
        "T_ee_cam deg",
        "RMS px",
        "wall s",
    ):
        t.add_column(col, justify="left" if col == "run" else "right")
    b = sim["baseline"]
    t.add_row(
        "baseline: nominal model (before calibration)",
        "-",
        f"{b['fx_error_pct']:+.2f}",
        f"{b['fy_error_pct']:+.2f}",
        f"{b['principal_point_error_px']:.2f}",
        f"{b['map_error_px']:.1f}",
        f"{b['hand_eye_mm']:.1f}",
        f"{b['hand_eye_deg']:.2f}",
        "-",
        "-",
    )
    for r in sim["rows"]:
        t.add_row(
            f"{r['board']} seed {r['seed']}",
            f"{r['views']} ({r['accepted']})",
            f"{r['fx_error_pct']:+.3f}",
            f"{r['fy_error_pct']:+.3f}",
            f"{r['principal_point_error_px']:.3f}",
            f"{r['map_error_px']:.3f}",
            f"{r['hand_eye_mm']:.3f}",
            f"{r['hand_eye_deg']:.4f}",
            f"{r['rms_px']:.3f}",
            f"{r['wall_s']:.1f}",
        )
    out.print(t)
    out.print("wall time: simulated driver at 8x real time, shared machine (rough)")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true", help="print one JSON object on the last line")
    ap.add_argument("--seeds", default="0,1,2", help="planner seeds, comma-separated")
    ap.add_argument("--boards", default="chessboard,charuco", help="boards, comma-separated")
    ap.add_argument("--poses", type=int, default=25, help="views planned per run")
    args = ap.parse_args(argv)
    seeds = [int(s) for s in args.seeds.split(",") if s.strip()]
    boards = [b.strip() for b in args.boards.split(",") if b.strip()]
    with Progress(console=err, transient=True) as progress:
        sim = bench_sim(seeds, boards, progress, n_poses=args.poses)
    print_sim(sim)
    if args.json:
        sys.stdout.write(json.dumps(sim) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
