"""Choosing calibration views: candidate camera poses around a board and a greedy pick of a
diverse, image-filling subset.

These are the pure pieces of automatic calibration in the cell.  The robot side (inverse
kinematics, joint limits, collisions) enters only through the ``feasible`` predicate of
:func:`plan_views`, so ``vision`` stays free of ``robot``: the cell passes a function that
maps ``T_base_cam`` to ``T_base_ee`` with its current ``T_ee_cam`` estimate and asks IK.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from vision.calibration.boards import Board
from vision.calibration.coverage import (
    CoverageMap,
    RotationDiversity,
    coverage_map,
    rotation_diversity,
)
from vision.camera import PinholeCamera

__all__ = ["ViewPlan", "board_centre", "candidate_camera_poses", "look_at", "plan_views"]


def look_at(
    eye: ArrayLike, target: ArrayLike, up: ArrayLike = (0.0, 0.0, 1.0)
) -> NDArray[np.float64]:
    """Camera pose (OpenCV axes: +z towards ``target``, +y roughly against ``up``) at ``eye``."""
    e = np.asarray(eye, dtype=np.float64)
    z = np.asarray(target, dtype=np.float64) - e
    if np.linalg.norm(z) == 0:
        raise ValueError(f"eye and target must differ, both are {e.tolist()}")
    z /= np.linalg.norm(z)
    u = np.asarray(up, dtype=np.float64)
    x = np.cross(z, -u)
    if np.linalg.norm(x) < 1e-9:
        x = np.cross(z, [1.0, 0.0, 0.0] if abs(z[0]) < 0.9 else [0.0, 1.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, y, z, e
    return T


def board_centre(board: Board) -> NDArray[np.float64]:
    """Centre of the board's corners in the board frame, metres."""
    return board.object_points().mean(axis=0)


def candidate_camera_poses(
    T_base_board: ArrayLike,
    board: Board,
    *,
    n: int = 300,
    distance_m: tuple[float, float] = (0.35, 0.6),
    max_tilt_deg: float = 40.0,
    max_roll_deg: float = 60.0,
    aim_jitter_m: float = 0.03,
    rng: np.random.Generator | None = None,
) -> NDArray[np.float64]:
    """Random camera poses ``T_base_cam`` (n, 4, 4) that look at the board's printed side.

    The camera sits on a spherical cap over the board centre (tilt from the board normal
    uniform in solid angle up to ``max_tilt_deg``, distance uniform in ``distance_m``),
    aims at the centre give or take ``aim_jitter_m`` and turns about its optical axis by up
    to ``max_roll_deg``.
    """
    if int(n) < 1:
        raise ValueError(f"n must be >= 1, got {n!r}")
    lo, hi = distance_m
    if not 0 < lo <= hi:
        raise ValueError(f"distance_m must satisfy 0 < low <= high, got {distance_m!r}")
    if not 0 <= max_tilt_deg < 90:
        raise ValueError(f"max_tilt_deg must be in [0, 90), got {max_tilt_deg!r}")
    gen = rng if rng is not None else np.random.default_rng(0)
    B = np.asarray(T_base_board, dtype=np.float64)
    c = board_centre(board)
    out = np.empty((int(n), 4, 4))
    cos_max = np.cos(np.radians(max_tilt_deg))
    for k in range(int(n)):
        cos_t = gen.uniform(cos_max, 1.0)
        sin_t = np.sqrt(1.0 - cos_t**2)
        phi = gen.uniform(0.0, 2.0 * np.pi)
        d = gen.uniform(lo, hi)
        # The printed side faces -z of the board frame.
        eye = c + d * np.array([sin_t * np.cos(phi), sin_t * np.sin(phi), -cos_t])
        aim = c + np.r_[gen.uniform(-aim_jitter_m, aim_jitter_m, 2), 0.0]
        T_board_cam = look_at(eye, aim, up=(0.0, -1.0, 0.0))
        roll = Rotation.from_rotvec(
            [0.0, 0.0, np.radians(gen.uniform(-max_roll_deg, max_roll_deg))]
        )
        T_board_cam[:3, :3] = T_board_cam[:3, :3] @ roll.as_matrix()
        out[k] = B @ T_board_cam
    return out


@dataclass(frozen=True)
class ViewPlan:
    """Views picked for a calibration run.

    Attributes
    ----------
    indices : tuple of int
        Indices of the picked candidates, in the order they should be visited.
    T_base_cam : ndarray of shape (k, 4, 4)
        Their camera poses.
    coverage : CoverageMap
        Where the board corners will fall in the image over all picked views.
    diversity : RotationDiversity
        Of the picked camera orientations.
    skipped : int
        Candidates refused as infeasible or with the board not fully in view.
    """

    indices: tuple[int, ...]
    T_base_cam: NDArray[np.float64]
    coverage: CoverageMap
    diversity: RotationDiversity
    skipped: int


def _min_angle_deg(R: NDArray[np.float64], chosen: list[NDArray[np.float64]]) -> float:
    if not chosen:
        return 180.0
    rel = np.einsum("ji,njk->nik", R, np.array(chosen))
    return float(np.degrees(Rotation.from_matrix(rel).magnitude()).min())


def plan_views(
    T_base_board: ArrayLike,
    board: Board,
    camera: PinholeCamera,
    candidates: ArrayLike,
    *,
    n_views: int = 15,
    feasible: Callable[[NDArray[np.float64]], bool] | None = None,
    margin_px: float = 8.0,
    coverage_weight: float = 2.0,
    grid: tuple[int, int] = (8, 6),
) -> ViewPlan:
    """Greedily pick ``n_views`` candidates that see the whole board and differ most.

    Each step takes the candidate with the largest score ``min_angle / 30 deg +
    coverage_weight * new_cells / all_cells``: ``min_angle`` is its smallest rotation
    angle to the views picked so far (rotation diversity, Tsai and Lenz) and ``new_cells``
    the coverage-grid cells its corners add (Zhang: distortion is fixed where corners are
    seen).  Candidates for which ``feasible(T_base_cam)`` is False (unreachable, colliding)
    or that do not show every corner ``margin_px`` inside the image are skipped.
    """
    B = np.asarray(T_base_board, dtype=np.float64)
    C = np.asarray(candidates, dtype=np.float64)
    if C.ndim != 3 or C.shape[1:] != (4, 4):
        raise ValueError(f"candidates must have shape (M, 4, 4), got {C.shape}")
    if int(n_views) < 1:
        raise ValueError(f"n_views must be >= 1, got {n_views!r}")
    obj = board.object_points()
    w, h = camera.width, camera.height
    usable: list[int] = []
    pixels: dict[int, NDArray[np.float64]] = {}
    for k, T in enumerate(C):
        uv = camera.project_world(obj, np.linalg.inv(T) @ B)
        inside = np.isfinite(uv).all() and (
            (uv[:, 0] >= margin_px).all()
            and (uv[:, 1] >= margin_px).all()
            and (uv[:, 0] <= w - 1 - margin_px).all()
            and (uv[:, 1] <= h - 1 - margin_px).all()
        )
        if inside and (feasible is None or feasible(T)):
            usable.append(k)
            pixels[k] = uv
    gc, gr = grid
    picked: list[int] = []
    rots: list[NDArray[np.float64]] = []
    covered = np.zeros((gr, gc), dtype=bool)
    remaining = list(usable)
    while remaining and len(picked) < int(n_views):
        best, best_score = -1, -np.inf
        for k in remaining:
            cells = coverage_map([pixels[k]], (w, h), grid=grid).counts > 0
            gain = np.count_nonzero(cells & ~covered) / covered.size
            score = _min_angle_deg(C[k, :3, :3], rots) / 30.0 + coverage_weight * gain
            if score > best_score:
                best, best_score = k, score
        picked.append(best)
        rots.append(C[best, :3, :3])
        covered |= coverage_map([pixels[best]], (w, h), grid=grid).counts > 0
        remaining.remove(best)
    T_sel = C[picked] if picked else np.zeros((0, 4, 4))
    return ViewPlan(
        indices=tuple(picked),
        T_base_cam=T_sel,
        coverage=coverage_map([pixels[k] for k in picked], (w, h), grid=grid),
        diversity=rotation_diversity(T_sel) if picked else RotationDiversity(0, 0.0, 0.0, 0.0),
        skipped=len(C) - len(usable),
    )
