"""``visioncell calibrate auto``: automatic calibration in the simulated cell, in this
process, compared with the simulator's ground truth.
"""

from __future__ import annotations

from typing import Annotated

import typer
from rich.table import Table

from backend.cli.calibration_common import JsonOpt, SaveOpt, _fail, _finish, _progress, out

__all__ = ["register"]


def register(group: typer.Typer) -> None:
    """Add ``auto`` to the ``calibrate`` command group."""
    group.command("auto")(calibrate_auto_cmd)


def calibrate_auto_cmd(
    board: Annotated[
        str, typer.Option("--board", help="Board of the simulated cell: chessboard or charuco")
    ] = "chessboard",
    poses: Annotated[int, typer.Option("--poses", help="Views to plan (3..60)")] = 25,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the view planner")] = 0,
    time_scale: Annotated[
        float, typer.Option("--time-scale", help="Simulated seconds per wall second (0.1..100)")
    ] = 8.0,
    as_json: JsonOpt = False,
    save: SaveOpt = None,
) -> None:
    """Automatic calibration in the simulated cell, in this process: plan reachable,
    collision-free views of the board on the table, move, grab, detect, solve intrinsics and
    hand-eye, and compare with the simulator's ground truth.  (On a running server, start
    it with POST /api/calibration/auto or the console's Calibration tab.)"""
    from backend.hardware import headless_mujoco

    headless_mujoco()
    from backend.calibration.simrun import run_sim_auto

    if board not in ("chessboard", "charuco"):
        raise _fail(f"board must be chessboard or charuco, got {board!r}")
    if not 3 <= poses <= 60:
        raise _fail(f"poses must be in [3, 60], got {poses}")
    if not 0.1 <= time_scale <= 100.0:
        raise _fail(f"time-scale must be in [0.1, 100], got {time_scale}")
    with _progress(True) as update:
        try:
            rep = run_sim_auto(
                board=board, n_poses=poses, seed=seed, time_scale=time_scale, progress=update
            )
        except RuntimeError as exc:
            raise _fail(str(exc)) from None
    if not as_json:
        r = rep.result
        out.print(
            f"[bold]automatic calibration[/bold] ({board}): {r['views']} views, "
            f"{r['accepted']} with the board, corners cover {r['coverage']:.0%} of the image "
            f"({r['corner_cells']} of 4 corners), rotations up to "
            f"{r['diversity']['max_angle_deg']:.0f} deg about axes "
            f"{r['diversity']['axis_spread_deg']:.0f} deg apart"
        )
        t = Table(title="against the simulator's ground truth")
        t.add_column("quantity")
        t.add_column("error", justify="right")
        t.add_column("target", justify="right")
        t.add_row("fx", f"{rep.fx_error_pct:+.3f} %", "<= 0.2 %")
        t.add_row("fy", f"{rep.fy_error_pct:+.3f} %", "<= 0.2 %")
        t.add_row("principal point", f"{rep.principal_point_error_px:.3f} px", "<= 1 px")
        t.add_row("undistortion map (max)", f"{rep.map_error_px:.3f} px", "<= 0.3 px")
        t.add_row("T_ee_cam translation", f"{rep.hand_eye_mm:.3f} mm", "<= 1 mm")
        t.add_row("T_ee_cam rotation", f"{rep.hand_eye_deg:.4f} deg", "<= 0.1 deg")
        out.print(t)
        out.print(
            f"reprojection RMS {r['rms_px']:.3f} px; run took {rep.wall_s:.1f} s wall time "
            f"(driver at {time_scale:g}x real time)"
        )
    _finish(rep.as_dict(), as_json, save)
