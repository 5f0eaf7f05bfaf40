"""The second top view: taken when the first one's pose rests on too little
(:func:`vision.pose.rests_on_too_little`), turned about the camera's axis, and the pose
computed there (:func:`second_top_view`)."""

from __future__ import annotations

import asyncio
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from backend.inspection import pose as pose_stage
from backend.inspection import results
from backend.inspection.context import Context, draw, travel_of
from backend.inspection.look import carried, look_with_region, plan_view
from backend.inspection.options import InspectOptions
from backend.inspection.stopwatch import Stopwatch
from robot.errors import Unreachable
from vision.pose import ObjectPose, PoseFailed, pose_apart, predict_along_belt, rests_on_too_little
from vision.recognition.light import apply_gain

__all__ = ["SECOND_TOP_ROLL_RAD", "SecondTop", "second_top_view"]

#: The second top view, taken when the first one's pose rests on too little
#: (:func:`rests_on_too_little`).  The camera turns about its axis by ``ROLL`` (one of
#: the teach's rolls: its camera centre relative to the object is a taught one's) at the
#: top view's distance; the region is the top view's carried over, widened by
#: ``MARGIN_PX`` only (the belt's own features round the object cost correspondences).
#: Measured with a second top view after every first one (pipe flange, seed 8, 40 objects
#: in index mode): roll 120 deg, margin 2 px: 39 of 40 within 2 mm and 1 deg, 40 joint
#: fits; roll 120 deg with the side views' margins (1 cm + 6 px): 37; roll 60 deg (a
#: camera centre not taught): 33; roll 60 deg at 0.30 m: 26.
SECOND_TOP_ROLL_RAD = math.radians(120.0)
SECOND_TOP_MARGIN_PX = 2
#: Two answers that each rest on too little (the first and the second top view's) are
#: taken when they agree within these (two images, each with its own features).
WEAK_AGREE_M = 0.0015
WEAK_AGREE_YAW_RAD = math.radians(0.75)


@dataclass(frozen=True, eq=False)
class SecondTop:
    """What the second top view gave: the pose to use (None: ``error``), the frame with its
    camera and its stored image (None when no frame was taken), whether the pose is of its
    exposure, and the summary stored with the pose."""

    pose: ObjectPose | None
    error: str
    shot: tuple[Any, NDArray[np.float64], results.ViewRecord] | None = None
    used: bool = False
    summary: dict[str, Any] = field(default_factory=dict)


def _weakness(pose: ObjectPose) -> str:
    if pose.method == "plane":
        return "the plane answer of one trained view: too few correspondences for the joint fit"
    return f"one trained view's {pose.n_points} correspondences"


def _pose_brief(pose: ObjectPose | None, err: str) -> dict[str, Any]:
    if pose is None:
        return {"error": err}
    return {"method": pose.method, "n_points": pose.n_points, "views": pose.views,
            "position_m": [round(float(v), 5) for v in pose.T_base_obj[:3, 3]],
            "yaw_rad": round(float(pose.yaw_rad), 5)}  # fmt: skip


async def second_top_view(
    ctx: Context, opts: InspectOptions, model: str, found: NDArray[np.float64], *,
    watch: Stopwatch,
    first: ObjectPose | None, first_err: str, T_plan: NDArray[np.float64],
    top_mask: NDArray[np.bool_], T_cam_top: NDArray[np.float64], height: float,
    travel0: float, gain: Any, mode: str, speed_m_s: float,
) -> SecondTop:  # fmt: skip
    """Look at the object from the top again (turned by :data:`SECOND_TOP_ROLL_RAD`; at
    constant speed over where the belt will have carried it) and compute the pose there,
    in the first top view's region ``top_mask`` carried into the new view
    (:func:`side_roi`, up to ``height``).

    The second view's pose is taken unless it too rests on too little
    (:func:`rests_on_too_little`); two such answers are taken when they agree within
    :data:`WEAK_AGREE_M` and :data:`WEAK_AGREE_YAW_RAD` (at constant speed the first
    carried by the belt's travel between the exposures); otherwise there is no pose, with
    the reason (a pose resting on one view's handful of features would be picked wrong)."""
    rt = ctx.rt
    summary: dict[str, Any] = {"first": _pose_brief(first, first_err)}

    def none(why: str, shot: Any = None) -> SecondTop:
        summary.setdefault("second", {"error": why})
        first_txt = (f"the top view's pose rested on too little ({_weakness(first)})"
                     if first is not None else first_err)  # fmt: skip
        return SecondTop(None, f"{first_txt}; the second top view: {why}", shot,
                          summary=summary)  # fmt: skip

    point = found
    if mode == "continuous":
        try:
            point = carried(ctx, found, travel0, speed_m_s, 1)
        except Unreachable as exc:
            return none(str(exc))
    try:
        plan = await plan_view(point, 1, T_plan, watch, roll_rad=SECOND_TOP_ROLL_RAD)
    except (Unreachable, ValueError) as exc:
        return none(f"cannot be reached: {exc}")
    f, T_cam, roi = await look_with_region(
        ctx, plan.views[0].q, watch=watch, top_mask=top_mask, T_cam_top=T_cam_top, height_m=height,
        travel0=travel0 if mode == "continuous" else None, speed=opts.speed,
        margin_m=0.0, margin_px=SECOND_TOP_MARGIN_PX,
    )  # fmt: skip
    second: ObjectPose | None = None
    err = ""
    mask = None if roi.mask is None else roi.mask.astype(bool)
    if mask is None:
        err = f"no region: {roi.reason}"
    else:
        feats = await asyncio.to_thread(rt.live_index.extract, apply_gain(f.rgb, gain), mask)
        try:
            second = await pose_stage.estimate(ctx, None, model, T_cam, height, feats, mask)
        except PoseFailed as exc:
            err = exc.detail
    summary["second"] = _pose_brief(second, err)
    label = f"vp1 again {model} {'-' if second is None else second.method}"
    record = results.ViewRecord(1, await asyncio.to_thread(draw, f.rgb, mask, label),
                                {"segmentation": "the top view's region carried over",
                                 "second_top_view": summary, "light_gain": None if gain is None
                                 else [round(float(g), 4) for g in gain]})  # fmt: skip
    shot = (f, T_cam, record)
    if second is None:
        return none(err, shot)
    if not rests_on_too_little(second):
        summary["chosen"] = "second"
        return SecondTop(second, "", shot, used=True, summary=summary)
    apart = ""
    if first is not None:
        first_now = first
        if mode == "continuous":  # the first carried by the belt's travel since the top view
            first_now = predict_along_belt(first, travel_of(f, rt) - travel0)
        d, dyaw = pose_apart(first_now, second)
        if d <= WEAK_AGREE_M and dyaw <= WEAK_AGREE_YAW_RAD:
            summary["chosen"] = "first"
            return SecondTop(first, "", shot, summary=summary)
        apart = f", {d * 1e3:.1f} mm and {math.degrees(dyaw):.1f} deg from the first"
    return none(f"too little again ({_weakness(second)}){apart}", shot)
