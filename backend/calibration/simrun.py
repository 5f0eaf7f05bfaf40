"""An automatic calibration run in a simulated cell, in this process (CLI and benchmark).

The cell is assembled by :class:`~backend.runtime.CellRuntime`, as ``visioncell serve``
assembles it (simulated driver and camera, a fresh SQLite database in a temporary folder,
no 3D view), a board is placed on the table preset,
and the same planner and job as ``POST /api/calibration/auto`` run.  Only after the run is
the result compared with the simulator's ground truth, for the report.
"""

from __future__ import annotations

import asyncio
import math
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from robot.kinematics.pose6 import rotation_angle

__all__ = ["SimAutoReport", "run_sim_auto"]


@dataclass(frozen=True)
class SimAutoReport:
    """An auto-calibration run in the simulator, judged against the truth.

    Attributes
    ----------
    result : dict
        The job's result (session, calibration ids, K, dist, T_ee_cam, views, coverage, ...).
    fx_error_pct, fy_error_pct : float
        Focal length errors, percent (signed).
    principal_point_error_px : float
        Distance of the principal point from the truth.
    map_error_px : float
        Largest difference of the undistortion maps (each model's own,
        ``initUndistortRectifyMap(K, dist, None, K)``) over the whole image.
    hand_eye_mm, hand_eye_deg : float
        ``T_ee_cam`` translation and rotation error.
    wall_s : float
        Wall time of the run (planning, moves, grabs, detection, solve).
    sim_time_scale : float
        Simulated seconds per wall second of the driver.
    """

    result: dict[str, Any]
    fx_error_pct: float
    fy_error_pct: float
    principal_point_error_px: float
    map_error_px: float
    hand_eye_mm: float
    hand_eye_deg: float
    wall_s: float
    sim_time_scale: float

    def as_dict(self) -> dict[str, Any]:
        """JSON form."""
        return {
            "fx_error_pct": self.fx_error_pct,
            "fy_error_pct": self.fy_error_pct,
            "principal_point_error_px": self.principal_point_error_px,
            "map_error_px": self.map_error_px,
            "hand_eye_mm": self.hand_eye_mm,
            "hand_eye_deg": self.hand_eye_deg,
            "wall_s": self.wall_s,
            "sim_time_scale": self.sim_time_scale,
            "result": self.result,
        }


def _judge(result: dict[str, Any], truth: Any) -> dict[str, float]:
    from vision.camera import PinholeCamera

    K = np.asarray(result["K"], dtype=np.float64)
    est = PinholeCamera(K, result["dist"], width=truth.width, height=truth.height)
    ref = PinholeCamera(truth.K, truth.dist, width=truth.width, height=truth.height)
    mx, my = est.undistort_maps(dtype=np.float64)
    tx, ty = ref.undistort_maps(dtype=np.float64)
    T = np.asarray(result["T_ee_cam"], dtype=np.float64)
    R = T[:3, :3].T @ truth.T_ee_cam[:3, :3]
    return {
        "fx_error_pct": 100.0 * (K[0, 0] / truth.K[0, 0] - 1.0),
        "fy_error_pct": 100.0 * (K[1, 1] / truth.K[1, 1] - 1.0),
        "principal_point_error_px": float(np.hypot(*(K[:2, 2] - truth.K[:2, 2]))),
        "map_error_px": float(np.nanmax(np.hypot(mx - tx, my - ty))),
        "hand_eye_mm": 1e3 * float(np.linalg.norm(T[:3, 3] - truth.T_ee_cam[:3, 3])),
        "hand_eye_deg": math.degrees(rotation_angle(R)),
    }


async def _run(
    folder: Path,
    *,
    board: str,
    n_poses: int,
    seed: int,
    time_scale: float,
    activate: bool,
    progress: Callable[[float, str], None] | None,
) -> SimAutoReport:
    from backend.calibration import auto
    from backend.db.migrate import upgrade
    from backend.runtime import CellRuntime
    from backend.settings import Settings

    url = f"sqlite+aiosqlite:///{folder / 'calibration.db'}"
    settings = Settings(
        database_url=url,
        var_dir=folder / "var",
        driver="sim",
        camera="sim",
        time_scale=time_scale,
        camera_fps=20.0,
        view3d_enabled=False,
        bootstrap_operator=False,
        sim_demo=False,
    )
    await asyncio.to_thread(upgrade, url)
    async with CellRuntime(settings) as rt:
        cell, db, sim = rt.cell, rt.database, rt.sim
        if sim is None or cell.world is None:
            raise RuntimeError("the simulated cell did not start")
        spec = next(s for s in sim.config.boards if s.kind == board)
        layout = sim.config.layout
        x, y = layout.table_centre_xy
        T = np.array(
            [
                [1.0, 0.0, 0.0, x - 0.12],
                [0.0, -1.0, 0.0, y + 0.1],
                [0.0, 0.0, -1.0, layout.table_top_z_m + 0.002],
                [0.0, 0.0, 0.0, 1.0],
            ]
        )
        sim.place_board(board, T)
        pattern = auto.pattern_of_sim_board(spec)
        t0 = time.monotonic()
        run = await auto.prepare_auto_calibration(
            cell,
            board=pattern,
            T_base_board=T,
            options=auto.AutoOptions(n_poses=n_poses, seed=seed, activate=activate, speed=1.0),
            world=cell.world,
        )

        async def body(job: Any) -> dict[str, Any]:
            return await auto.run_auto_calibration(job, cell, db, run)

        job = cell.jobs.start("auto_calibrate", body, motion=True)
        task = job.task
        if task is None:  # JobManager.start always creates the task
            raise RuntimeError("the auto-calibration job has no task")
        while not task.done():
            if progress is not None:
                progress(job.progress, job.message)
            await asyncio.sleep(0.1)
        await cell.jobs.wait(job)
        wall = time.monotonic() - t0
        if job.error is not None:
            raise RuntimeError(f"{job.error['error']}: {job.error['detail']}")
        if job.result is None:
            raise RuntimeError(f"the run ended {job.state.value}")
        if progress is not None:
            progress(1.0, job.message)
        judged = _judge(job.result, sim.truth.camera)
        return SimAutoReport(job.result, wall_s=wall, sim_time_scale=time_scale, **judged)


def run_sim_auto(
    *,
    board: str = "chessboard",
    n_poses: int = 25,
    seed: int = 0,
    time_scale: float = 8.0,
    activate: bool = True,
    progress: Callable[[float, str], None] | None = None,
) -> SimAutoReport:
    """Run one automatic calibration in a fresh simulated cell and judge it (see module doc)."""
    if board not in ("chessboard", "charuco"):
        raise ValueError(f"board must be 'chessboard' or 'charuco', got {board!r}")
    if not 0.1 <= time_scale <= 100.0:
        raise ValueError(f"time_scale must be in [0.1, 100], got {time_scale!r}")
    with tempfile.TemporaryDirectory(prefix="visioncell-auto-") as tmp:
        return asyncio.run(
            _run(
                Path(tmp),
                board=board,
                n_poses=n_poses,
                seed=seed,
                time_scale=time_scale,
                activate=activate,
                progress=progress,
            )
        )
