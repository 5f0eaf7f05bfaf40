"""Arm poses for an automatic calibration run: diverse, reachable, collision-free, board in view.

The 5-DOF arm cannot point its camera anywhere: the approach axis stays in the vertical
plane through the column (chapter eq. 20), so candidate views are generated in the arm's
own terms, then judged with the camera model:

1. pick an aim point on or near the board (offsets move the board about the image), an
   approach angle ``phi = q2 + q3 + q4`` around the one that faces the board, a distance
   along the approach axis and a roll ``q5``; ``q1`` follows from the aim point's azimuth
   (:func:`robot.aiming.aimed_flange_pose`, the geometry the inspection's viewpoint
   planner shares);
2. solve the flange pose with the analytic IK (:func:`robot.kinematics.ik`, joint ranges
   checked), refuse it if an arm link or the camera comes near the table, the conveyor, the
   floor or the board (:class:`robot.collision.CollisionWorld`);
3. project the board's corners with the current camera model (the nominal one before any
   calibration) and keep the pose only if every corner is ``margin_px`` inside the image
   and the board is seen from its printed side at no more than ``max_view_angle_deg``;
4. pick views greedily for rotation diversity and image coverage, the image's corners
   first (Tsai and Lenz 1989 for the rotations, Zhang 2000 for the coverage) and order
   them for short moves.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robot.aiming import aimed_flange_pose
from robot.collision import Box, CollisionWorld
from robot.errors import Unreachable
from robot.kinematics import T_base_ee, ik
from robot.model import ASEA, ArmModel
from vision.calibration import Board, coverage_map
from vision.camera import PinholeCamera

__all__ = [
    "NOMINAL_T_EE_CAM",
    "AutoPlan",
    "PlannedView",
    "board_box",
    "plan_calibration_poses",
    "survey_views",
]

#: The camera's mounting from the drawing, before any hand-eye calibration: on the approach
#: axis, 4 cm past the flange, image x along ``y_ee`` (OpenCV camera frame).
NOMINAL_T_EE_CAM = np.array(
    [[0.0, -1.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.04], [0.0, 0.0, 0.0, 1.0]]
)
NOMINAL_T_EE_CAM.setflags(write=False)


@dataclass(frozen=True)
class PlannedView:
    """One pose of the plan.

    Attributes
    ----------
    q : ndarray (5,)
        Joints, radians.
    T_base_cam : ndarray (4, 4)
        Camera pose predicted with the planning model.
    corners_px : ndarray (N, 2)
        Where the board's corners are predicted in the image.
    """

    q: NDArray[np.float64]
    T_base_cam: NDArray[np.float64]
    corners_px: NDArray[np.float64]


@dataclass(frozen=True)
class AutoPlan:
    """Views to visit: ``views[:n_primary]`` first, the rest as reserves for unmet criteria.

    Attributes
    ----------
    views : tuple of PlannedView
    n_primary : int
    candidates : int
        Candidate poses generated.
    refused : dict
        Candidates refused, by reason: ``unreachable`` (IK or joint ranges), ``collision``,
        ``not_in_view`` (a corner outside the margin, or the board seen edge-on or from behind).
    """

    views: tuple[PlannedView, ...]
    n_primary: int
    candidates: int
    refused: dict[str, int]

    def as_dict(self) -> dict[str, object]:
        """JSON summary (no arrays)."""
        return {
            "views": len(self.views),
            "primary": self.n_primary,
            "candidates": self.candidates,
            "refused": dict(self.refused),
        }


def board_box(board: Board, T_base_board: ArrayLike, *, pad_m: float = 0.03) -> Box:
    """An axis-aligned box round the board's plate (its corners with one square of border,
    2 cm of thickness behind the face) grown by ``pad_m``."""
    B = np.asarray(T_base_board, dtype=np.float64)
    obj = board.object_points()
    s = board.square_m
    lo, hi = obj.min(axis=0)[:2] - 1.5 * s, obj.max(axis=0)[:2] + 1.5 * s
    pts = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (0, 0.02)])
    return Box.around("board", pts @ B[:3, :3].T + B[:3, 3], pad_m=pad_m)


def _in_view(uv: NDArray[np.float64], camera: PinholeCamera, margin_px: float) -> bool:
    w, h = camera.width, camera.height
    return bool(
        np.isfinite(uv).all()
        and (uv[:, 0] >= margin_px).all()
        and (uv[:, 1] >= margin_px).all()
        and (uv[:, 0] <= w - 1 - margin_px).all()
        and (uv[:, 1] <= h - 1 - margin_px).all()
    )


def plan_calibration_poses(
    T_base_board: ArrayLike,
    board: Board,
    camera: PinholeCamera,
    *,
    T_ee_cam: ArrayLike = NOMINAL_T_EE_CAM,
    world: CollisionWorld | None = None,
    n_poses: int = 25,
    n_reserve: int = 10,
    n_candidates: int = 3000,
    distance_m: tuple[float, float] = (0.2, 0.45),
    max_tilt_deg: float = 35.0,
    max_roll_deg: float = 75.0,
    aim_offset_m: float = 0.25,
    max_view_angle_deg: float = 45.0,
    margin_px: float = 20.0,
    q_start: ArrayLike | None = None,
    seed: int = 0,
    seen_px: Sequence[ArrayLike] = (),
    seen_T_base_cam: ArrayLike | None = None,
    model: ArmModel = ASEA,
) -> AutoPlan:
    """Plan ``n_poses`` views of the board (plus up to ``n_reserve`` reserves).

    Parameters
    ----------
    T_base_board : ndarray (4, 4)
        Where the board is believed to be (board frame of ``board``; printed face towards
        -z of the board frame).  A few centimetres of error are absorbed by ``margin_px``
        and by re-planning after the first view.
    board : Board
        The pattern (its corners are what must be in view).
    camera : PinholeCamera
        The camera model used to predict the image (nominal before calibration).
    T_ee_cam : ndarray (4, 4)
        The camera's mounting used for the prediction.
    world : CollisionWorld, optional
        Obstacles; the board's own box is added.  Default: the floor only.
    n_poses, n_reserve : int
        Views in the plan and reserves after them.
    n_candidates : int
        Random candidates drawn (seeded by ``seed``).
    distance_m : (float, float)
        Range of the distance from the flange to the aim point along the approach axis.
    max_tilt_deg : float
        Largest deviation of the approach angle from the one facing the board.
    max_roll_deg : float
        Range of ``q5`` about its centre.
    aim_offset_m : float
        Largest offset of the aim point from the board centre (moves the board towards the
        image's edges and corners).
    max_view_angle_deg : float
        Largest angle between the line of sight and the board's normal.
    margin_px : float
        Every corner must be predicted this far inside the image.
    q_start : ndarray (5,), optional
        Where the arm is (IK seed, first move); default ``model.q_ready``.
    seed : int
        Random seed.
    seen_px, seen_T_base_cam : optional
        Corners (list of (N_i, 2) pixel arrays) and camera poses (k, 4, 4) of views already
        taken: the choice then favours the image cells and the rotations they lack.
    model : ArmModel
        The arm.

    Returns
    -------
    AutoPlan

    Raises
    ------
    Unreachable
        Fewer than 6 usable candidates (board out of reach, blocked or facing away); the
        message gives the counts per reason.
    ValueError
        Bad parameters.
    """
    B = np.asarray(T_base_board, dtype=np.float64)
    if B.shape != (4, 4) or not np.isfinite(B).all():
        raise ValueError(f"T_base_board must be a finite 4x4 matrix, got shape {B.shape}")
    if int(n_poses) < 3:
        raise ValueError(f"n_poses must be >= 3, got {n_poses!r}")
    if int(n_reserve) < 0:
        raise ValueError(f"n_reserve must be >= 0, got {n_reserve!r}")
    lo, hi = distance_m
    if not 0.05 < lo <= hi:
        raise ValueError(f"distance_m must satisfy 0.05 < low <= high, got {distance_m!r}")
    Tec = np.asarray(T_ee_cam, dtype=np.float64)
    rng = np.random.default_rng(seed)
    q0 = np.asarray(model.q_ready if q_start is None else q_start, dtype=np.float64)
    base_world = world if world is not None else CollisionWorld(model=model)
    obstacles = base_world.with_boxes(board_box(board, B))
    obj = board.object_points()
    centre_board = obj.mean(axis=0)
    centre = B[:3, :3] @ centre_board + B[:3, 3]
    normal_out = -B[:3, 2]  # the printed face looks towards -z of the board frame
    # The approach angle that looks straight at the face (from the horizontal, eq. 20).
    phi0 = math.asin(float(np.clip(-normal_out[2], -1.0, 1.0)))
    u_board, v_board = B[:3, 0], B[:3, 1]
    cos_view = math.cos(math.radians(max_view_angle_deg))
    T_cam_base_of = []
    qs: list[NDArray[np.float64]] = []
    pix: list[NDArray[np.float64]] = []
    refused = {"unreachable": 0, "collision": 0, "not_in_view": 0}
    for _ in range(int(n_candidates)):
        off = rng.uniform(-aim_offset_m, aim_offset_m, 2)
        aim = centre + off[0] * u_board + off[1] * v_board
        phi = phi0 + math.radians(rng.uniform(-max_tilt_deg, max_tilt_deg))
        phi = min(max(phi, -math.pi + 1e-3), math.pi - 1e-3)
        d = rng.uniform(lo, hi)
        roll = math.radians(rng.uniform(-max_roll_deg, max_roll_deg))
        pose = aimed_flange_pose(aim, phi_rad=phi, distance_m=d)
        try:
            q = ik(pose, roll=roll, seed=q0, model=model)
        except Unreachable:
            refused["unreachable"] += 1
            continue
        T_bc = T_base_ee(q, model) @ Tec
        sight = centre - T_bc[:3, 3]
        dist = float(np.linalg.norm(sight))
        if dist < 1e-6 or float(-sight @ normal_out) / dist < cos_view:
            refused["not_in_view"] += 1
            continue
        uv = camera.project_world(obj, np.linalg.inv(T_bc) @ B)
        if not _in_view(uv, camera, margin_px):
            refused["not_in_view"] += 1
            continue
        if obstacles.collides(q):
            refused["collision"] += 1
            continue
        qs.append(q)
        pix.append(uv)
        T_cam_base_of.append(T_bc)
    if len(qs) < 6:
        raise Unreachable(
            f"the board at {np.round(centre, 3).tolist()} m cannot be calibrated from here: "
            f"of {n_candidates} candidate poses {refused['unreachable']} are out of reach or "
            f"joint range, {refused['collision']} collide, {refused['not_in_view']} do not show "
            f"the whole board; {len(qs)} usable, need at least 6"
        )
    cands = np.array(T_cam_base_of)
    prior_R = (
        np.zeros((0, 3, 3))
        if seen_T_base_cam is None
        else np.asarray(seen_T_base_cam, dtype=np.float64).reshape(-1, 4, 4)[:, :3, :3]
    )
    idx = _pick(
        cands,
        pix,
        (camera.width, camera.height),
        int(n_poses) + int(n_reserve),
        seen_px=[np.asarray(p, dtype=np.float64).reshape(-1, 2) for p in seen_px],
        seen_R=prior_R,
    )
    n_primary = min(int(n_poses), len(idx))
    order = _short_tour([qs[i] for i in idx[:n_primary]], q0) + list(range(n_primary, len(idx)))
    views = tuple(PlannedView(qs[idx[k]], cands[idx[k]], pix[idx[k]]) for k in order)
    return AutoPlan(views, n_primary, int(n_candidates), refused)


def survey_views(
    T_base_board: ArrayLike,
    board: Board,
    camera: PinholeCamera,
    *,
    T_ee_cam: ArrayLike = NOMINAL_T_EE_CAM,
    world: CollisionWorld | None = None,
    margin_px: float = 80.0,
    n: int = 3,
    q_start: ArrayLike | None = None,
    model: ArmModel = ASEA,
) -> list[PlannedView]:
    """Up to ``n`` views for locating the board: straight on (or nearly), as far away as the
    arm reaches (0.65 m down to 0.3 m), the board ``margin_px`` inside the image, so that
    an uncalibrated camera model still sees all of it; farthest first."""
    B = np.asarray(T_base_board, dtype=np.float64)
    q0 = np.asarray(model.q_ready if q_start is None else q_start, dtype=np.float64)
    obstacles = (world or CollisionWorld(model=model)).with_boxes(board_box(board, B))
    obj = board.object_points()
    centre = B[:3, :3] @ obj.mean(axis=0) + B[:3, 3]
    phi0 = math.asin(float(np.clip(B[2, 2], -1.0, 1.0)))  # facing the printed side
    Tec = np.asarray(T_ee_cam, dtype=np.float64)
    out: list[PlannedView] = []
    for d in np.arange(0.65, 0.299, -0.05):
        for dphi, roll in ((0, 0), (10, 0), (-10, 0), (0, 30), (0, -30), (20, 0), (-20, 0)):
            phi = phi0 + math.radians(dphi)
            try:
                q = ik(
                    aimed_flange_pose(centre, phi_rad=phi, distance_m=float(d)),
                    roll=math.radians(roll),
                    seed=q0,
                    model=model,
                )
            except Unreachable:
                continue
            T_bc = T_base_ee(q, model) @ Tec
            uv = camera.project_world(obj, np.linalg.inv(T_bc) @ B)
            if _in_view(uv, camera, margin_px) and not obstacles.collides(q):
                out.append(PlannedView(q, T_bc, uv))
                break
        if len(out) >= n:
            break
    return out


def _pick(
    T: NDArray[np.float64],
    pix: list[NDArray[np.float64]],
    size: tuple[int, int],
    n: int,
    *,
    seen_px: Sequence[NDArray[np.float64]] = (),
    seen_R: NDArray[np.float64] | None = None,
    grid: tuple[int, int] = (8, 6),
) -> list[int]:
    """Greedy choice for rotation diversity and coverage (cf. :func:`vision.calibration.plan_views`).

    Score of a candidate: ``min_angle / 30 deg + sum over the grid cells it covers of
    (2 / n_cells + 0.5 [corner cell]) / (1 + views already covering the cell)``, with
    ``min_angle`` its smallest rotation to the views already picked (Tsai and Lenz) and the
    cells those of the coverage grid its corners fall in (Zhang).  Cells seen by few views
    weigh most, and the image's four corner cells extra: distortion is largest there and
    only fixed by corners seen there, so they are worth several views each.
    """
    cells = [coverage_map([p], size, grid=grid).counts > 0 for p in pix]
    weight = np.full((grid[1], grid[0]), 2.0 / (grid[0] * grid[1]))
    weight[[0, 0, -1, -1], [0, -1, 0, -1]] += 0.5
    R = T[:, :3, :3]
    min_angle = np.full(len(pix), 180.0)
    seen = np.zeros(weight.shape)
    for p in seen_px:  # views already taken
        seen += coverage_map([p], size, grid=grid).counts > 0
    for Rs in np.zeros((0, 3, 3)) if seen_R is None else seen_R:
        min_angle = np.minimum(min_angle, _angles_deg(Rs, R))
    picked: list[int] = []
    left = set(range(len(pix)))
    while left and len(picked) < n:
        gain = weight / (1.0 + seen)
        best, best_score = -1, -np.inf
        for k in sorted(left):
            score = min_angle[k] / 30.0 + float(gain[cells[k]].sum())
            if score > best_score:
                best, best_score = k, score
        picked.append(best)
        left.discard(best)
        seen += cells[best]
        min_angle = np.minimum(min_angle, _angles_deg(R[best], R))
    return picked


def _angles_deg(R0: NDArray[np.float64], R: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rotation angles between ``R0`` (3, 3) and each of ``R`` (n, 3, 3), degrees."""
    rel = np.einsum("ji,njk->nik", R0, R)
    return np.degrees(np.arccos(np.clip((np.trace(rel, axis1=1, axis2=2) - 1) / 2, -1, 1)))


def _short_tour(qs: list[NDArray[np.float64]], q0: NDArray[np.float64]) -> list[int]:
    """Nearest-neighbour order of ``qs`` from ``q0`` (largest joint change as the distance,
    which is what a synchronised move's duration follows)."""
    left = list(range(len(qs)))
    out: list[int] = []
    cur = q0
    while left:
        k = min(left, key=lambda i: float(np.abs(qs[i] - cur).max()))
        out.append(k)
        left.remove(k)
        cur = qs[k]
    return out
