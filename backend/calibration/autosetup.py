"""What an automatic calibration run (:mod:`backend.calibration.auto`) needs before its job
starts: its options and stopping criteria, the planning camera model, the first plan of
views (:func:`prepare_auto_calibration`)."""

from __future__ import annotations

import asyncio
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from backend.calibration.autoplan import NOMINAL_T_EE_CAM, AutoPlan, plan_calibration_poses
from robot.collision import CollisionWorld
from vision.calibration import Board, CharucoBoard, Chessboard, ViewSetCriteria
from vision.camera import PinholeCamera

if TYPE_CHECKING:
    from backend.cell import Cell

#: When collection may stop: >= 12 views with the board found, corners in >= 70 % of an
#: 8 x 6 grid over the image and in >= 3 of its 4 corner cells (Zhang 2000: distortion is
#: only fixed where corners are seen), robot orientations differing by >= 30 deg and turning
#: about axes >= 30 deg apart (Tsai and Lenz 1989).
AUTO_CRITERIA = ViewSetCriteria(
    min_views=12,
    min_coverage=0.7,
    min_corner_cells=3,
    min_max_angle_deg=30.0,
    min_axis_spread_deg=30.0,
)


def pattern_of_sim_board(spec: Any) -> Chessboard | CharucoBoard:
    """The calibration pattern printed on one of the simulated cell's boards
    (``robot.sim.boards.BoardSpec``: kind, cols, rows, square and marker sizes, dictionary)."""
    if spec.kind == "chessboard":
        return Chessboard(spec.cols, spec.rows, spec.square_m)
    return CharucoBoard(spec.cols, spec.rows, spec.square_m, spec.marker_m, spec.dictionary)


def nominal_camera(width: int, height: int, *, fovy_deg: float = 60.0) -> PinholeCamera:
    """The camera model before any calibration: square pixels, centred principal point,
    no distortion, focal length from the lens's nominal vertical field of view."""
    return PinholeCamera.from_fov(fovy_deg, width=width, height=height)


@dataclass(frozen=True)
class AutoOptions:
    """Options of an automatic run.

    Attributes
    ----------
    n_poses : int
        Views planned (reserves come on top while the criteria are unmet).
    n_reserve : int
        Reserve views.
    activate : bool
        Activate the solution.
    seed : int
        Seed of the planner.
    speed : float
        Fraction of the arm's speed limits, [0.01, 1].
    criteria : ViewSetCriteria
        When collection may stop (``min_views`` is capped at ``n_poses``).
    settle_s : float
        Wall-clock wait after a move, after which the run also waits for the arm to be
        still (``backend.cell.STILL_RAD_S``) before the frame is taken.
    """

    n_poses: int = 25
    n_reserve: int = 10
    activate: bool = False
    seed: int = 0
    speed: float = 0.6
    criteria: ViewSetCriteria = field(default_factory=lambda: AUTO_CRITERIA)
    settle_s: float = 0.05

    def __post_init__(self) -> None:
        if not 3 <= int(self.n_poses) <= 60:
            raise ValueError(f"n_poses must be in [3, 60], got {self.n_poses!r}")
        if not 0 <= int(self.n_reserve) <= 60:
            raise ValueError(f"n_reserve must be in [0, 60], got {self.n_reserve!r}")
        if not 0.01 <= float(self.speed) <= 1.0:
            raise ValueError(f"speed must be in [0.01, 1], got {self.speed!r}")


@dataclass(frozen=True)
class AutoRun:
    """Everything a run needs, checked before the job starts.

    Attributes
    ----------
    board : Board
    T_base_board : ndarray (4, 4)
        Where the board is believed to be (a starting guess).
    options : AutoOptions
    world : CollisionWorld
        The cell's obstacles.
    camera : PinholeCamera
        Planning model (nominal before calibration).
    T_ee_cam : ndarray (4, 4)
        Planning mounting.
    plan : AutoPlan
        The first plan (from the guess).
    """

    board: Board
    T_base_board: NDArray[np.float64]
    options: AutoOptions
    world: CollisionWorld
    camera: PinholeCamera
    T_ee_cam: NDArray[np.float64]
    plan: AutoPlan


def _plan(B: NDArray[np.float64], q: NDArray[np.float64], **kw: Any) -> AutoPlan:
    """Plan from the board pose ``B`` with the arm at ``q`` (keywords: see :class:`AutoRun`)."""
    o: AutoOptions = kw["options"]
    n = kw.get("n_poses") or o.n_poses
    return plan_calibration_poses(
        B,
        kw["board"],
        kw["camera"],
        T_ee_cam=kw["T_ee_cam"],
        world=kw["world"],
        n_poses=n,
        n_reserve=o.n_reserve,
        margin_px=kw.get("margin_px", 20.0),
        seen_px=kw.get("seen_px", ()),
        seen_T_base_cam=kw.get("seen_T_base_cam"),
        q_start=q,
        seed=o.seed,
        model=kw["model"],
    )


async def prepare_auto_calibration(
    cell: Cell,
    *,
    board: Board,
    T_base_board: NDArray[np.float64],
    options: AutoOptions,
    world: CollisionWorld,
    camera: PinholeCamera | None = None,
    T_ee_cam: NDArray[np.float64] | None = None,
) -> AutoRun:
    """Plan the first views (raises :class:`~robot.errors.Unreachable` when the board cannot
    be seen from any reachable, collision-free pose) and fix the planning model: ``camera``
    and ``T_ee_cam`` default to :func:`nominal_camera` of the camera's frame size and
    :data:`NOMINAL_T_EE_CAM`."""
    B = np.asarray(T_base_board, dtype=np.float64)
    if camera is None:
        frame = await cell.next_frame(after=0.0)
        h, w = frame.rgb.shape[:2]
        camera = nominal_camera(w, h)
    Tec = np.asarray(NOMINAL_T_EE_CAM if T_ee_cam is None else T_ee_cam, dtype=np.float64)
    kw = {"options": options, "board": board, "camera": camera, "T_ee_cam": Tec, "world": world}
    first = await asyncio.to_thread(
        _plan, B, np.asarray(cell.driver.state.q, dtype=np.float64), model=cell.model, **kw
    )
    return AutoRun(board, B, options, world, camera, Tec, first)
