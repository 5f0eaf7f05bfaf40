"""The recognise stage: the top view segmented, the views recognised
(:func:`vision.recognition.recognise_views` with the live index and the thresholds in force;
its ``look`` gives the top view for viewpoint 1 and moves the arm to side viewpoints 2 / 3
planned from where the top view found the part), and the decision with its reason."""

from __future__ import annotations

import asyncio
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from backend.inspection import results
from backend.inspection.context import (
    Context,
    TopPlan,
    belt_state,
    cam_pose,
    draw,
    station_px,
    truth_near,
)
from backend.inspection.draft import InspectionDraft
from backend.inspection.find import Found, add_look
from backend.inspection.look import WHOLE_IMAGE_NOTE, WholeImage, carried, plan_view, side_view
from backend.inspection.options import InspectOptions
from backend.planning import AIM_HEIGHT_M
from backend.recognition import thresholds
from backend.recognition.segment import segment_object
from vision.pose import plane_points
from vision.recognition import recognise_views
from vision.recognition.light import apply_gain, light_gain, surround_colour
from vision.segmentation.roi import height_bound, side_query

__all__ = ["UNKNOWN_MAX_HEIGHT_M", "TopView", "recognise"]

#: What the cell assumes of an object it cannot name (no stored height): the tallest the
#: station admits (its viewpoints aim for objects up to this), metres.
UNKNOWN_MAX_HEIGHT_M = 0.25


@dataclass(eq=False)
class TopView:
    """What the recognise stage leaves the pose and sort stages: the recognition's result,
    the top view's region, camera pose and query features, the light's gain, the belt's
    mode, speed and travel at the top view's exposure, and whether the view was taken
    whole (no empty-belt background)."""

    res: Any
    mask: NDArray[np.bool_]
    T_cam: NDArray[np.float64]
    gain: Any
    mode: str
    speed_m_s: float
    travel0: float
    whole: bool
    features: list[Any] = field(default_factory=list)


async def recognise(ctx: Context, opts: InspectOptions, plan: TopPlan, part: Found,
                    draft: InspectionDraft, report: Any) -> TopView:  # fmt: skip
    """Segment the top view, recognise the views and decide (module docstring), filling
    ``draft``."""
    rt, cell, watch = ctx.rt, ctx.rt.cell, draft.watch
    live = rt.live_index
    frame, travel0, bg = part.frame, part.travel_m, part.bg
    # No empty-belt background (a real or recorded camera whose models were imported or
    # uploaded: only a teach grabs one): the top view is recognised whole, said so.
    whole = bg is None
    report(0.1, "inspecting the part at the station")
    mode, speed_m_s, _ = belt_state(rt)
    T_cam_top = cam_pose(frame.robot_state.q, ctx.T_ee_cam)
    z_mid = ctx.surface_z + AIM_HEIGHT_M / 2
    draft.stage = "segmenting"
    if bg is None:  # whole
        region: Any = WholeImage(np.ones(frame.rgb.shape[:2], dtype=bool))
    else:
        with watch.stage("segment"):
            near = None if mode == "continuous" else station_px(ctx, T_cam_top, z_mid)
            region = await asyncio.to_thread(segment_object, frame.rgb, bg, near_px=near)
    ys, xs = np.nonzero(region.mask)
    found = plane_points(np.array([[xs.mean(), ys.mean()]]), ctx.camera, T_cam_top, z_mid)[0]
    found[2] = ctx.surface_z
    draft.found = found
    draft.truth = truth_near(rt, found, belt_state(rt)[2] - travel0)
    # The light: every view's channels scaled back to the light the views were taught
    # under, by the belt round the object now against the belt in the trained top views.
    gain = None
    if opts.balance_light and not whole:
        gain = light_gain(live.light_reference(), surround_colour(frame.rgb, region.mask))
    draft.light_gain = None if gain is None else [round(float(g), 4) for g in gain]
    top = TopView(None, region.mask, T_cam_top, gain, mode, speed_m_s, travel0, whole)
    frames: dict[int, tuple[Any, NDArray[np.bool_] | None, str]] = {
        1: (frame, region.mask, region.method)
    }
    draft.cams.append(T_cam_top)
    notes: list[str] = []
    roi_height = height_bound(
        (m.height_m for m in live.models().values()), default_m=UNKNOWN_MAX_HEIGHT_M
    )

    async def look(vp: int) -> Any:
        if vp == 1:
            feats = await asyncio.to_thread(live.extract, apply_gain(frame.rgb, gain), region.mask)
            top.features.append(feats)
            return feats
        draft.stage = f"viewpoint {vp}"
        report(0.3 + 0.2 * len(frames), f"viewpoint {vp}")
        point = carried(ctx, found, travel0, speed_m_s, vp) if mode == "continuous" else found
        if whole:  # no top-view region to carry over: the side view is recognised whole
            planned = await plan_view(point, vp, plan.T_plan, watch)
            with watch.pause():
                f = await cell.look(planned.views[0].q, speed=opts.speed)
            add_look(watch, f)
            draft.cams.append(cam_pose(f.robot_state.q, ctx.T_ee_cam))
            frames[vp] = (f, None, WHOLE_IMAGE_NOTE)
            return apply_gain(f.rgb, gain)
        side = await side_view(
            ctx, vp, point, watch=watch, T_plan=plan.T_plan, top_mask=region.mask,
            T_cam_top=T_cam_top, height_m=roi_height,
            travel0=travel0 if mode == "continuous" else None, speed=opts.speed,
        )  # fmt: skip
        notes.extend(side.notes)
        draft.cams.append(side.T_base_cam)
        frames[vp] = (side.frame, None if side.roi.mask is None else side.roi.mask.astype(bool),
                      side.roi.reason)  # fmt: skip
        return side_query(apply_gain(side.frame.rgb, gain), side.roi)

    choice = plan.choice
    if opts.threshold is not None:
        choice = thresholds.choice_from_detail(
            float(opts.threshold), {"rule": f"fixed by recipe {opts.recipe_name or ''}".strip()}
        )
    draft.stage = "recognition"
    with watch.stage("features"), live.reading() as index:
        res = await recognise_views(look, index, policy=opts.policy, max_views=opts.max_views,
                                    threshold=choice)  # fmt: skip
        # the verification's share, as the recognition timed it
        watch.credit("match", sum(r.verification_s for r in res.views))
    top.res = res
    with watch.stage("decide"):
        await _decide(ctx, opts, draft, res, frames, notes, whole)
    return top


async def _decide(ctx: Context, opts: InspectOptions, draft: InspectionDraft, res: Any,
                  frames: dict[int, tuple[Any, NDArray[np.bool_] | None, str]],
                  notes: list[str], whole: bool) -> None:  # fmt: skip
    """The views' stored images and the decision (recognized, unknown) with its reason."""
    live = ctx.rt.live_index
    draft.viewpoints = res.viewpoints
    draft.scores = {k: round(float(v), 4) for k, v in res.scores.items()}
    for vp, r in zip(res.viewpoints, res.views, strict=True):
        f, m, how = frames[vp]
        label = f"vp{vp} {r.best_model or '-'} {r.score:.2f}"
        draft.views.append(results.ViewRecord(vp, await asyncio.to_thread(draw, f.rgb, m, label),
                                              {"segmentation": how, "decision": r.decision,
                                               "light_gain": draft.light_gain,
                                               "scores": {k: round(float(s), 4)
                                                          for k, s in r.scores.items()}}))  # fmt: skip
    if res.decision == "recognized" and opts.models and res.model not in opts.models:
        draft.decision, draft.score = "unknown", float(res.score)
        draft.reason = (f"{res.model} scored {res.score:.2f}: not a model of recipe "
                        f"{opts.recipe_name or '(options)'}")  # fmt: skip
    elif res.decision == "recognized":
        draft.decision, draft.model, draft.score = "recognized", res.model, float(res.score)
        indexed = None if res.model is None else live.model_of_name(res.model)
        draft.model_id = None if indexed is None else indexed.id
        draft.reason = f"{res.model} scored {res.score:.2f} over {len(res.viewpoints)} view(s)"
    else:
        draft.decision, draft.score = "unknown", float(res.score)
        if res.decision == "ambiguous" and len(res.contenders) > 1:
            draft.reason = f"ambiguous between {', '.join(res.contenders)}"
        elif res.decision == "ambiguous":
            draft.reason = (f"{res.contenders[0]} not confirmed by the side views "
                            f"(fused score {res.score:.2f})")  # fmt: skip
        else:
            draft.reason = f"no model passed its threshold (best score {res.score:.2f})"
    if notes:
        draft.reason += "; " + "; ".join(notes)
    if whole:
        draft.reason += f"; {WHOLE_IMAGE_NOTE}"
    if ctx.uncalibrated:
        draft.reason += f"; camera: {ctx.source}"
