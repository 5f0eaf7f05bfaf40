"""One teach round at its planned shots (steps 3 to 5 of :mod:`backend.recognition.teach`):
look at each shot and segment the object against its empty-belt background, store the
trained views, measure the part's height, choose the threshold, and say what was done.

The shots, their backgrounds and the wait for the object come from the teach job
(:func:`backend.recognition.teach.run_teach`); nothing here plans or waits.
"""

from __future__ import annotations

import asyncio
import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from backend import audit
from backend.db.session import Database
from backend.heavy import HeavyPool
from backend.planning import Shot
from backend.recognition import thresholds
from backend.recognition.autothreshold import ThresholdKeeper
from backend.recognition.geometry import Silhouette, TopShot
from backend.recognition.index import LiveIndex
from backend.recognition.models import taught_rounds
from backend.recognition.segment import SegmentationFailed, segment_object
from backend.recognition.teachheight import measure, store_geometry
from backend.recognition.teachoptions import TeachOptions, rounds_guide
from backend.recognition.views import ViewInput, add_views, view_public
from robot.kinematics import T_base_ee
from vision.camera import PinholeCamera
from vision.features.types import Features

__all__ = ["Looked", "look_at_shots", "store_round"]


@dataclass
class Looked:
    """What the round saw at its shots, in the order of the shots."""

    #: The views to store (the shots that are not for the height alone).
    inputs: list[ViewInput] = field(default_factory=list)
    #: Per shot: viewpoint, roll, joints seen, mask size, segmentation, timings.
    shots: list[dict[str, Any]] = field(default_factory=list)
    #: Per shot: the object's region and the camera pose it was seen from.
    silhouettes: list[tuple[Shot, Silhouette]] = field(default_factory=list)
    #: Width and height of the frames, pixels.
    frame_size: tuple[int, int] = (640, 480)


async def look_at_shots(
    job: Any,
    cell: Any,
    shots: list[Shot],
    backgrounds: dict[int, NDArray[np.uint8]],
    *,
    options: TeachOptions,
    T_ee_cam_seen: NDArray[np.float64],
    done: int,
    steps: int,
) -> Looked:
    """Visit each shot (move, settle, a frame exposed after the arm was still), segment
    the object with the active contour initialised from the background difference
    (:mod:`backend.recognition.segment`); progress runs from ``done`` to ``done +
    len(shots)`` of ``steps``."""
    n = len(shots)
    looked = Looked()
    for k, shot in enumerate(shots):
        job.report(
            done / steps,
            f"view {k + 1}/{n}: viewpoint {shot.viewpoint}, "
            f"roll {math.degrees(shot.roll_rad):.0f} deg",
        )
        t0 = time.monotonic()
        frame = await cell.look(shot.q, speed=options.speed)
        t1 = time.monotonic()
        try:
            region = await asyncio.to_thread(segment_object, frame.rgb, backgrounds[k])
        except SegmentationFailed as exc:
            raise SegmentationFailed(f"viewpoint {shot.viewpoint}: {exc.detail}") from exc
        mask = region.mask
        state = frame.robot_state
        q_seen = np.asarray(getattr(state, "q", shot.q), dtype=np.float64)
        looked.frame_size = (int(frame.rgb.shape[1]), int(frame.rgb.shape[0]))
        looked.silhouettes.append((shot, Silhouette(mask, T_base_ee(q_seen) @ T_ee_cam_seen)))
        looked.shots.append(
            {
                "viewpoint": shot.viewpoint,
                "roll_rad": shot.roll_rad,
                "joints": [float(v) for v in q_seen],
                "mask_px": int(mask.sum()),
                "segmentation": region.method,
                "segmentation_note": region.note,
                "planner": shot.reason,
                "look_s": round(t1 - t0, 3),
                "segment_s": round(time.monotonic() - t1, 3),
                "geometry_only": shot.geometry_only,
            }
        )
        done += 1
        if shot.geometry_only:
            continue
        looked.inputs.append(
            ViewInput(
                frame.rgb,
                shot.viewpoint,
                mask,
                yaw_rad=options.yaw_rad,
                roll_rad=shot.roll_rad,
                source="teach",
                joints=q_seen,
                T_base_cam=shot.T_base_cam,
                name=f"viewpoint {shot.viewpoint} roll {math.degrees(shot.roll_rad):.0f} deg",
            )
        )
    return looked


async def store_round(
    job: Any,
    looked: Looked,
    *,
    db: Database,
    live: LiveIndex,
    model: dict[str, Any],
    options: TeachOptions,
    station_z_m: float,
    progress: float,
    by: audit.By | None,
    heavy: HeavyPool | None,
    camera: PinholeCamera | None,
    keeper: ThresholdKeeper | None,
) -> dict[str, Any]:
    """Store the views of ``looked`` in one transaction, then in the live index; measure
    the part's height (:mod:`backend.recognition.geometry`) and store it with ``model``
    (``{"id", "name", "kind"}``); choose the threshold (deferred, through ``keeper``, or
    at once on ``heavy``); the teach's result.  ``station_z_m``: the station point's
    height, base frame, metres; ``progress``: the fraction reported meanwhile."""
    model_id, kind = int(model["id"]), str(model["kind"])
    job.report(progress, "storing the views")
    # A view with too few features (one roll of a plain face, say) is left out and said;
    # the round fails only when no top view would be left.
    weak: list[tuple[int, str]] = []
    rows = await add_views(db, live, model_id, looked.inputs, replace=options.replace, by=by,
                           skipped=weak, needs_viewpoint=1)  # fmt: skip
    left_out = {k for k, _ in weak}
    for _, why in weak:
        job.report(progress, f"left out: {why}")
    job.report(progress, "measuring the part's height")
    silhouettes = looked.silhouettes
    shot_views = [sil for sil in silhouettes if not sil[0].geometry_only]  # as ``inputs``
    stored = [sil for k, sil in enumerate(shot_views) if k not in left_out]
    tops = [
        TopShot(Features.from_bytes(r.features), sil.T_base_cam)
        for r, (shot, sil) in zip(rows, stored, strict=True)
        if shot.viewpoint == 1 and r.viewpoint == 1
    ]
    geometry = await measure(silhouettes, tops, camera, looked.frame_size, station_z_m)
    geometry_out = await store_geometry(db, live, model_id, geometry)
    async with db.session() as session:
        taught = (await taught_rounds(session, [model_id]))[model_id]
    if not options.threshold:
        outcome = await thresholds.deferred(db)
    elif keeper is not None:
        job.report(1.0, "choosing the threshold")
        outcome = await keeper.choose(
            lambda f, msg: job.report(1.0, f"choosing the threshold: {msg}")
        )
    else:
        job.report(1.0, "choosing the threshold")
        outcome = await thresholds.recompute(db, live, heavy=heavy)
    return {
        "model": {"id": model_id, "name": model["name"], "kind": kind},
        "views": [view_public(r) for r in rows],
        "shots": looked.shots,
        "left_out": [why for _, why in weak],
        "geometry": geometry_out,
        "threshold": outcome.public(),
        "confusable_from_top": list(outcome.confusable),
        "rounds": rounds_guide(taught, thresholds.recommended_rounds(kind)),
    }
