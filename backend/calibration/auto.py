"""Automatic calibration in the cell: move through planned poses, grab, detect, solve, store.

One run is one motion job (it holds the arm until it ends):

1. a hand-eye session (``source="auto"``) is created;
2. the arm goes to the plan's first view (the board centred, seen nearly straight on); the
   board's pose is measured there with the planning camera model (PnP), and the views are
   planned again around that measurement, so that a rough board placement is enough;
3. for each view: ``cell.look`` (a joint move collision-checked along the path with the
   board as an extra obstacle, settle, a frame exposed after the arm stopped), store the
   frame with the joints and ``T_base_ee`` from the encoders at exposure (the board is
   detected when the sample is stored);
4. collection stops when the planned views are done and the criteria hold (stated in
   :data:`AUTO_CRITERIA`); reserves are visited while they do not; with none left the run
   fails, the samples stay in the session;
5. intrinsics and hand-eye are solved from the session (:func:`solve_session`) and,
   if asked, activated.

Cancelling (or an e-stop, which cancels motion jobs) stops the run between two steps;
nothing is solved or activated then.

The options, the planning model and the first plan (what is checked before the job starts)
are in :mod:`backend.calibration.autosetup`, re-exported here.
"""

from __future__ import annotations

import asyncio
import dataclasses
import functools
import time
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np
from numpy.typing import NDArray

from backend.calibration.autoplan import AutoPlan, PlannedView, board_box, survey_views
from backend.calibration.autosetup import (
    AUTO_CRITERIA,
    AutoOptions,
    AutoRun,
    _plan,
    nominal_camera,
    pattern_of_sim_board,
    prepare_auto_calibration,
)
from backend.calibration.sessions import (
    SampleIn,
    add_samples,
    cell_id_of,
    create_session,
    get_session,
)
from backend.calibration.solving import SolveOptions, solve_session
from backend.cell.errors import PathBlocked
from backend.cell.viewlog import CalibrationViewLog
from backend.db.models import CalibrationKind
from robot.kinematics import T_base_ee
from vision.calibration import (
    Board,
    Detection,
    HandEyeOptions,
    IntrinsicsOptions,
    RotationDiversity,
    calibrate_hand_eye,
    calibrate_intrinsics_from_detections,
    coverage_map,
    detect_pattern,
    rotation_diversity,
)
from vision.camera import PinholeCamera
from vision.errors import CalibrationError

if TYPE_CHECKING:
    from backend.cell import Cell
    from backend.db.session import Database
    from backend.jobs import Job

__all__ = [
    "AUTO_CRITERIA",
    "AutoOptions",
    "AutoRun",
    "CalibrationViewLog",
    "nominal_camera",
    "pattern_of_sim_board",
    "prepare_auto_calibration",
    "run_auto_calibration",
]

#: Survey views tried before the run gives up on finding the board.
SURVEY_TRIES = 3
#: Accepted views after which the planning model is replaced by a quick calibration.
UPDATE_AFTER_VIEWS = 6


def _detection(corners: Any, size: tuple[int, int]) -> Detection:
    a = np.asarray(corners, dtype=np.float64).reshape(-1, 3)
    return Detection(True, a[:, 1:3].copy(), a[:, 0].astype(np.int64), size, "stored", "")


def _quick_model(
    dets: list[Detection], poses: list[NDArray[np.float64]], board: Board
) -> tuple[PinholeCamera, NDArray[np.float64], NDArray[np.float64]] | None:
    """Camera, ``T_ee_cam`` and ``T_base_board`` from the views so far: intrinsics with
    radial terms only, then Tsai and Lenz's closed form without refinement; None if the
    views do not allow it yet."""
    try:
        intr = calibrate_intrinsics_from_detections(
            dets, board, options=IntrinsicsOptions(radial_only=True, reject_outliers=False)
        )
        he = calibrate_hand_eye(
            dets,
            np.array(poses),
            board,
            intr.camera,
            options=HandEyeOptions(methods=("tsai",), refine=False),
        )
    except (CalibrationError, ValueError):
        return None
    return intr.camera, he.T_ee_cam, he.T_base_board


def _diversity(poses: list[NDArray[np.float64]]) -> RotationDiversity:
    return rotation_diversity(np.array(poses, dtype=np.float64).reshape(-1, 4, 4))


def _measure_board(
    image: NDArray[np.uint8], board: Board, camera: PinholeCamera, T_base_cam: NDArray[np.float64]
) -> NDArray[np.float64] | None:
    """The board's pose in the base frame from one image with the planning model (PnP)."""
    det = detect_pattern(image, board)
    if not det.found:
        return None
    ok, rvec, tvec = cv2.solvePnP(
        det.object_points(board),
        np.asarray(det.image_points, dtype=np.float64).reshape(-1, 1, 2),
        camera.K,
        camera.dist,
    )
    if not ok:
        return None
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(rvec)[0]
    T[:3, 3] = tvec.ravel()
    return T_base_cam @ T


async def run_auto_calibration(job: Job, cell: Cell, db: Database, run: AutoRun) -> dict[str, Any]:
    """The body of an ``auto_calibrate`` motion job (see the module docstring)."""
    t0 = time.monotonic()
    log = cell.calibration_views
    log.clear()
    board, options, world, cam, Tec = run.board, run.options, run.world, run.camera, run.T_ee_cam
    w, h = cam.width, cam.height
    crit = options.criteria
    crit = dataclasses.replace(crit, min_views=min(crit.min_views, options.n_poses))

    current: dict[str, Any] = {"camera": cam, "T_ee_cam": Tec, "margin_px": 20.0}

    def plan(B: NDArray[np.float64], n_poses: int | None = None, **seen: Any) -> AutoPlan:
        return _plan(
            B,
            np.asarray(cell.driver.state.q, dtype=np.float64),
            model=cell.model,
            options=options,
            board=board,
            world=world,
            n_poses=n_poses,
            **current,
            **seen,
        )

    first = run.plan
    async with db.session() as s:
        cell_id = await cell_id_of(s, cell.name)
        row = await create_session(
            s,
            kind=CalibrationKind.hand_eye,
            board=board,
            cell_id=cell_id,
            source="auto",
            note=f"automatic: {options.n_poses} poses, seed {options.seed}",
        )
        session_id = row.id
    job.params["session_id"] = session_id

    # Survey views: far and straight on, so that the nominal model's errors cannot push
    # the board out of the image; the planned views' most compact ones if none exists.
    surveys = await asyncio.to_thread(
        survey_views,
        run.T_base_board,
        board,
        cam,
        T_ee_cam=Tec,
        world=world,
        n=SURVEY_TRIES,
        q_start=np.asarray(cell.driver.state.q, dtype=np.float64),
        model=cell.model,
    )
    if not surveys:
        centre = np.array([(w - 1) / 2.0, (h - 1) / 2.0])
        surveys = sorted(
            first.views, key=lambda v: float(np.linalg.norm(v.corners_px - centre, axis=1).max())
        )[:SURVEY_TRIES]
    B = None
    guarded = world.with_boxes(board_box(board, run.T_base_board))
    for n_try, survey in enumerate(surveys, start=1):
        job.report(0.01, f"survey view {n_try}: locating the board")
        try:
            frame = await cell.look(
                survey.q, speed=options.speed, world=guarded, settle_s=options.settle_s
            )
        except PathBlocked:
            continue
        q_seen = np.asarray(frame.robot_state.q, dtype=np.float64)
        B = await asyncio.to_thread(
            _measure_board, frame.rgb, board, cam, T_base_ee(q_seen, cell.model) @ Tec
        )
        if B is not None:
            break
    if B is None:
        raise CalibrationError(
            f"the board was not found from {len(surveys)} survey views (or they could not be "
            "reached without collision): check that it is placed where the request says and "
            "that it is lit"
        )
    guarded = world.with_boxes(board_box(board, B))
    views = list((await asyncio.to_thread(plan, B)).views)
    n_primary = min(options.n_poses, len(views))
    points: list[NDArray[np.float64]] = []
    dets: list[Detection] = []
    poses: list[NDArray[np.float64]] = []
    visited = 0
    unmet: list[str] = ["no views yet"]

    async def store(name: str, image: NDArray[np.uint8], q: NDArray[np.float64]) -> None:
        T_be = T_base_ee(q, cell.model)
        async with db.session() as s2:
            cal = await get_session(s2, session_id)
            rows = await add_samples(
                s2, cal, [SampleIn(name=name, image=image, joints=q.tolist(), T_base_ee=T_be)]
            )
            ok = rows[0].accepted
            if ok:
                dets.append(_detection(rows[0].corners, (w, h)))
                points.append(np.asarray(rows[0].corners, dtype=np.float64).reshape(-1, 3)[:, 1:3])
                poses.append(T_be)
        log.add(T_be @ current["T_ee_cam"], ok)

    await store("auto-00.png", frame.rgb, q_seen)  # the survey view is a sample too
    k = 0
    updated = False
    skipped: list[str] = []
    while k < len(views):
        v: PlannedView = views[k]
        k += 1
        if k > n_primary and not unmet:
            break
        visited += 1
        job.report(
            0.85 * min(visited / max(n_primary, 1), 1.0),
            f"view {visited} of {n_primary}{' (reserve)' if k > n_primary else ''}: "
            f"{len(poses)} with the board",
        )
        try:
            frame = await cell.look(
                v.q, speed=options.speed, world=guarded, settle_s=options.settle_s
            )
        except PathBlocked as exc:
            skipped.append(exc.detail)
            continue
        q_seen = np.asarray(frame.robot_state.q, dtype=np.float64)
        await store(f"auto-{visited:02d}.png", frame.rgb, q_seen)
        if not updated and len(poses) >= UPDATE_AFTER_VIEWS:
            # Plan the rest with the camera model measured so far (the nominal one
            # misplaces the board by tens of pixels near the image's edges).
            updated = True
            job.report(job.progress, f"updating the camera model from {len(poses)} views")
            better = await asyncio.to_thread(_quick_model, dets, poses, board)
            if better is not None:
                current["camera"], current["T_ee_cam"], B = better
                guarded = world.with_boxes(board_box(board, B))
                current["margin_px"] = 16.0
                left = max(n_primary - k, 3)
                seen_T = np.array([T @ current["T_ee_cam"] for T in poses])
                fresh_plan = await asyncio.to_thread(
                    functools.partial(plan, B, left, seen_px=list(points), seen_T_base_cam=seen_T)
                )
                fresh = list(fresh_plan.views)
                views = views[:k] + fresh
                n_primary = k + left
        cov = coverage_map(points, (w, h))
        div = _diversity(poses)
        unmet = crit.unmet(cov, div)
    cov = coverage_map(points, (w, h))
    div = _diversity(poses)
    unmet = crit.unmet(cov, div)
    if unmet:
        raise CalibrationError(
            f"collection criteria not met after {visited + 1 - len(skipped)} views (session {session_id} keeps "
            f"the samples): {'; '.join(unmet)}"
        )
    job.report(0.86, f"solving intrinsics and hand-eye from {len(poses)} views")
    async with db.session() as s:
        out = await solve_session(
            s,
            session_id,
            SolveOptions(intrinsics_source="session", activate=options.activate),
            progress=lambda f, m: job.report(0.86 + 0.14 * f, m),
        )
        cal = out.calibration
        result: dict[str, Any] = {
            "session_id": session_id,
            "calibration_id": cal.id,
            "intrinsic_calibration_id": None if out.intrinsic is None else out.intrinsic.id,
            "active": cal.active,
            "rms_px": cal.rms_px,
            "T_ee_cam": cal.parameters["T_ee_cam"],
            "K": cal.parameters["K"],
            "dist": cal.parameters["dist"],
        }
    result.update(
        {
            "views": visited + 1 - len(skipped),
            "accepted": len(poses),
            "coverage": cov.fraction,
            "corner_cells": cov.corner_cells,
            "diversity": div.as_dict(),
            "skipped": skipped,
            "duration_s": time.monotonic() - t0,
        }
    )
    job.report(1.0, f"calibration {result['calibration_id']}: RMS {result['rms_px']:.3f} px")
    return result
