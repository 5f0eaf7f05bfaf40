"""Teaching a model with the arm: the chapter's training of section 3.5,
done by the cell.

With the object at the station the job

1. plans the viewpoints from the station point (:func:`robot.viewpoints.
   plan_viewpoints`, the planner inspections use): the top view (1) for a ``2d`` model; the
   top and the two side views (2 inner, 3 outer) for a ``3d`` one.  The top view is taken at
   several camera rolls about the optical axis (joint q5, :data:`TOP_ROLLS_RAD`), so a model
   is recognised at any yaw on the belt (how many was chosen by measurement: ``python -m
   benchmarks.teach_yaw``);
2. has an empty-belt background for each shot: grabbed first (``background="grab"``: the
   station must be empty; the job then waits until an object has arrived and lies still) or
   taken from an earlier teach with the same shots (``background="stored"``);
3. visits each shot (move, settle, and a frame exposed after the arm was still:
   ``cell.look``), segments the object with the active contour initialised from the
   background difference (:mod:`backend.recognition.segment`), extracts the features inside
   the object's region and stores the trained view (image, mask, features, joints, camera
   pose) in one transaction with the others, then in the live index;
4. measures the part's height (:mod:`backend.recognition.geometry`): from the features
   the top views at their three rolls share (triangulated), else from the top view's and
   the side views' regions (a 2d model's teach takes one side view more for this alone),
   and stores it with the model unless an engineer entered one: the pick needs it.  When
   it cannot be measured the result says so and the console asks for it;
5. recomputes the automatic threshold (:mod:`backend.recognition.thresholds`) and reports
   the models confusable from the top, with what to add when the views are too few.

Progress is reported per shot.  Nothing is stored unless every shot succeeded.  This
module plans the round, has its backgrounds, waits for the object and starts the job; the
round at the shots (steps 3 to 5) is :mod:`backend.recognition.teachround`.
"""

from __future__ import annotations

import asyncio
import math
import time
from typing import Any

import numpy as np
from numpy.typing import NDArray

from backend import audit
from backend.db.session import Database
from backend.heavy import HeavyPool
from backend.planning import BackgroundStore, Shot, mounting_or_nominal, plan_shots
from backend.recognition.autothreshold import ThresholdKeeper
from backend.recognition.index import LiveIndex
from backend.recognition.models import get_model
from backend.recognition.segment import SegmentationFailed, foreground_mask
from backend.recognition.teachheight import geometry_shot
from backend.recognition.teachoptions import (
    MAX_ROUNDS,
    MAX_WAIT_S,
    TOP_ROLLS_RAD,
    TeachOptions,
    rounds_guide,
    teach_yaws_rad,
)
from backend.recognition.teachround import look_at_shots, store_round
from robot.collision import CollisionWorld
from vision.camera import PinholeCamera
from vision.errors import Conflict, InvalidInput, VisionCellError
from vision.segmentation import iou

__all__ = [
    "MAX_ROUNDS",
    "MAX_WAIT_S",
    "TOP_ROLLS_RAD",
    "TeachOptions",
    "TeachTimeout",
    "check_live_camera",
    "rounds_guide",
    "run_teach",
    "start_teach",
    "teach_yaws_rad",
]


class TeachTimeout(VisionCellError):
    """No object arrived at the station in time."""

    code = "teach_timeout"


async def _wait_for_object(
    cell: Any, shot: Shot, background: NDArray[np.uint8], wait_s: float, job: Any
) -> None:
    """Watch the top view until an object lies still at the station."""
    deadline = time.monotonic() + wait_s
    last: NDArray[np.bool_] | None = None
    job.report(job.progress, "waiting for an object at the station")
    while True:
        frame = await cell.look(None)
        try:
            mask = await asyncio.to_thread(foreground_mask, frame.rgb, background)
        except SegmentationFailed:
            mask = None
        if mask is not None and last is not None and iou(mask, last) > 0.97:
            return  # there, and not moving
        last = mask
        if time.monotonic() >= deadline:
            raise TeachTimeout(
                f"no object lay still at the station within {wait_s:g} s of grabbing the "
                "background; place the object and teach again with background='stored'"
            )
        await asyncio.sleep(0.3)


async def run_teach(
    job: Any,
    *,
    cell: Any,
    db: Database,
    live: LiveIndex,
    model_id: int,
    options: TeachOptions,
    point: NDArray[np.float64],
    T_ee_cam: NDArray[np.float64],
    store: BackgroundStore,
    world: CollisionWorld | None = None,
    by: audit.By | None = None,
    heavy: HeavyPool | None = None,
    camera: PinholeCamera | None = None,
    T_ee_cam_seen: NDArray[np.float64] | None = None,
    keeper: ThresholdKeeper | None = None,
) -> dict[str, Any]:
    """The teach job's body (module docstring); runs holding the arm.

    Parameters
    ----------
    job : Job
        For progress reports.
    cell : Cell
        Provides ``await cell.look(q, speed=...)`` (move, settle, fresh frame).
    point : ndarray of shape (3,)
        The station point (footprint centre of the object), base frame, metres.
    T_ee_cam : ndarray of shape (4, 4)
        Camera mounting (the active hand-eye calibration, or the nominal one).
    store : BackgroundStore
        Backgrounds of earlier teaches (read for ``"stored"``, written for ``"grab"``).
    camera : PinholeCamera, optional
        The camera model, for measuring the part's height (default: the nominal lens for
        the frames' size).
    T_ee_cam_seen : ndarray of shape (4, 4), optional
        The camera mounting the images are measured with (default ``T_ee_cam``): the
        planner keeps the nominal mounting so the shots (and their stored backgrounds)
        stay the same, the measurement needs the best one known.
    keeper : ThresholdKeeper, optional
        The cell's automatic threshold keeper: held while the teach runs, and the choice
        at its end is made through it (the same choice the keeper would make, once).
    """
    if keeper is None:
        return await _teach(job, cell=cell, db=db, live=live, model_id=model_id,
                            options=options, point=point, T_ee_cam=T_ee_cam, store=store,
                            world=world, by=by, heavy=heavy, camera=camera,
                            T_ee_cam_seen=T_ee_cam_seen, keeper=None)  # fmt: skip
    async with keeper.holding():
        return await _teach(job, cell=cell, db=db, live=live, model_id=model_id,
                            options=options, point=point, T_ee_cam=T_ee_cam, store=store,
                            world=world, by=by, heavy=heavy, camera=camera,
                            T_ee_cam_seen=T_ee_cam_seen, keeper=keeper)  # fmt: skip


async def _teach(
    job: Any,
    *,
    cell: Any,
    db: Database,
    live: LiveIndex,
    model_id: int,
    options: TeachOptions,
    point: NDArray[np.float64],
    T_ee_cam: NDArray[np.float64],
    store: BackgroundStore,
    world: CollisionWorld | None,
    by: audit.By | None,
    heavy: HeavyPool | None,
    camera: PinholeCamera | None,
    T_ee_cam_seen: NDArray[np.float64] | None,
    keeper: ThresholdKeeper | None,
) -> dict[str, Any]:
    T_seen = np.asarray(T_ee_cam if T_ee_cam_seen is None else T_ee_cam_seen, dtype=np.float64)
    async with db.session() as session:
        model = await get_model(session, model_id)
        kind, name = model.kind.value, model.name
    vps = options.viewpoints or ((1,) if kind == "2d" else (1, 2, 3))
    shots = await asyncio.to_thread(
        plan_shots,
        point,
        vps,
        T_ee_cam=T_ee_cam,
        object_height_m=options.object_height_m,
        top_rolls_rad=options.top_rolls_rad,
        world=world,
    )
    if 1 in vps and not any(s.viewpoint in (2, 3) for s in shots):
        # No side view among the views to store: one more, for the height alone.
        extra = await asyncio.to_thread(
            geometry_shot, point, T_ee_cam, options.object_height_m, world
        )
        if extra is not None and (options.background == "grab" or store.get(extra) is not None):
            shots.append(extra)
    n = len(shots)
    steps = 2 * n if options.background == "grab" else n
    done = 0
    backgrounds: dict[int, NDArray[np.uint8]] = {}
    if options.background == "grab":
        for k, shot in enumerate(shots):
            job.report(done / steps, f"background {k + 1}/{n}: viewpoint {shot.viewpoint}")
            frame = await cell.look(shot.q, speed=options.speed)
            backgrounds[k] = frame.rgb
            store.put(shot, frame.rgb)
            done += 1
        first = await cell.look(shots[0].q, speed=options.speed)
        await _wait_for_object(cell, shots[0], backgrounds[0], options.wait_s, job)
        del first
    else:
        for k, shot in enumerate(shots):
            bg = store.get(shot)
            if bg is None:
                raise InvalidInput(
                    f"no stored background for viewpoint {shot.viewpoint} at roll "
                    f"{math.degrees(shot.roll_rad):.0f} deg: teach once with background='grab'"
                )
            backgrounds[k] = bg
    looked = await look_at_shots(job, cell, shots, backgrounds, options=options,
                                 T_ee_cam_seen=T_seen, done=done, steps=steps)  # fmt: skip
    done += n
    return await store_round(
        job,
        looked,
        db=db,
        live=live,
        model={"id": model_id, "name": name, "kind": kind},
        options=options,
        station_z_m=float(point[2]),
        progress=done / steps,
        by=by,
        heavy=heavy,
        camera=camera,
        keeper=keeper,
    )


def check_live_camera(cell: Any) -> None:
    """Refuse (409) a teach on a camera that replays a recording (the folder camera, a video
    file): the arm cannot make it look at the object at the station, and a replay never
    shows an object lying still on an empty belt.  Recorded images become trained views by
    import instead."""
    cam = getattr(getattr(cell, "feed", None), "camera", None)
    if getattr(cam, "recorded", False) is True:
        raise Conflict(
            f"the {getattr(cam, 'name', 'recorded')} camera replays recorded images: a teach "
            "needs a live camera the arm points at the object.  Import the images as trained "
            "views instead: `visioncell models import NAME FOLDER` (or POST "
            "/api/models/{id}/views)"
        )


async def start_teach(
    *,
    cell: Any,
    db: Database,
    live: LiveIndex,
    model_id: int,
    options: TeachOptions,
    store: BackgroundStore,
    point: NDArray[np.float64] | None = None,
    by: audit.By | None = None,
    heavy: HeavyPool | None = None,
    camera: PinholeCamera | None = None,
    mounting: NDArray[np.float64] | None = None,
    keeper: ThresholdKeeper | None = None,
) -> Any:
    """Check what can be checked at once (the model exists, the arm is free), then start
    the teach as a motion job; returns the job.  ``heavy`` (the runtime's heavy-work pool)
    runs the threshold choice at its end, or ``keeper`` (the cell's automatic threshold
    keeper, held while the teach runs) makes it.

    ``point`` defaults to the station point of the cell's conveyor; the camera mounting is
    the active hand-eye calibration of the cell, else the nominal one; the camera model
    and mounting the part's height is measured with: the active calibration, else
    ``camera`` and ``mounting`` (the simulator's nominal ones, as inspections take them),
    else the nominal lens and mounting.
    """
    from backend.calibration import active_camera_calibration
    from robot.cellworld import CellLayout

    async with db.session() as session:
        await get_model(session, model_id)
        cell_id = getattr(cell, "db_id", None)
        T_ee_cam = None
        if cell_id is not None:
            cal = await active_camera_calibration(session, cell_id)
            T_ee_cam = cal.T_ee_cam
            camera = cal.camera or camera
    T = mounting_or_nominal(T_ee_cam)
    T_seen = T if T_ee_cam is not None or mounting is None else np.asarray(mounting, np.float64)
    p = np.asarray(CellLayout().station_point if point is None else point, dtype=np.float64)
    if p.shape != (3,) or not np.all(np.isfinite(p)) or np.linalg.norm(p[:2]) > 1.6:
        raise InvalidInput(
            f"point must be 3 finite coordinates within 1.6 m of the column, got {p}"
        )
    cell.check_can_move()
    check_live_camera(cell)

    async def body(job: Any) -> dict[str, Any]:
        return await run_teach(
            job,
            cell=cell,
            db=db,
            live=live,
            model_id=model_id,
            options=options,
            point=p,
            T_ee_cam=T,
            store=store,
            by=by,
            heavy=heavy,
            camera=camera,
            T_ee_cam_seen=T_seen,
            keeper=keeper,
        )

    params = {
        "model_id": model_id,
        "background": options.background,
        "viewpoints": list(options.viewpoints) if options.viewpoints else None,
        "top_rolls_rad": list(options.top_rolls_rad),
        "point": [float(v) for v in p],
        "hand_eye": "active" if T_ee_cam is not None else "nominal",
    }
    return cell.jobs.start("teach", body, motion=True, params=params)
