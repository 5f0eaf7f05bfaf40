"""The stages after the part is found, in order: recognise
(:mod:`backend.inspection.recognise`), pose (:func:`pose_part`, with
:mod:`backend.inspection.pose` and :mod:`backend.inspection.secondtop`) and sort
(:mod:`backend.inspection.sort`), each filling the inspection's draft and timed on its
stopwatch (:func:`run_stages`)."""

from __future__ import annotations

import asyncio
import contextlib
from dataclasses import dataclass
from typing import Any

from backend.inspection import pose as pose_stage
from backend.inspection import secondtop
from backend.inspection.context import Context, TopPlan, belt_state, travel_of
from backend.inspection.draft import InspectionDraft
from backend.inspection.find import Found
from backend.inspection.options import InspectOptions
from backend.inspection.recognise import TopView, recognise
from backend.inspection.sort import sort_part
from backend.planning import AIM_HEIGHT_M
from vision.pose import ObjectPose, PoseFailed, predict_along_belt, rests_on_too_little

__all__ = ["Posed", "pose_part", "run_stages"]


@dataclass(eq=False)
class Posed:
    """What the pose stage found: the pose (None: ``error`` says why), the model's stored
    height and grasp point, the belt's travel at the exposure the pose is of and the
    second top view's summary (None: none taken)."""

    pose: ObjectPose | None
    error: str
    stored_h: float | None
    grasp: Any
    travel: float
    second: dict[str, Any] | None = None


async def run_stages(ctx: Context, opts: InspectOptions, plan: TopPlan, part: Found,
                     draft: InspectionDraft, report: Any) -> None:  # fmt: skip
    """Recognise, pose and sort the part found (``part``), filling ``draft``."""
    rt, watch = ctx.rt, draft.watch
    top = await recognise(ctx, opts, plan, part, draft, report)
    with watch.stage("pose"):
        posed = await pose_part(ctx, opts, plan, top, draft, report)
        belt_stopped = False
        if top.mode == "continuous" and opts.sort and rt.conveyor.controllable:
            # Picking from a moving belt would need conveyor tracking the 5-DOF arm's
            # controller has not: the cell stops the belt (the encoder then says where the
            # object is: the prediction below is exact) and starts it again after the pick.
            await rt.conveyor.stop()
            belt_stopped = True
        pose = _publish_pose(ctx, top, draft, posed)
    draft.stage = "pick"
    assert draft.found is not None  # the recognise stage found the part on the belt
    with watch.stage("pick"):
        try:
            await sort_part(ctx, opts, draft, pose, posed.stored_h, draft.radius, posed.grasp,
                            draft.found, top.mode, top.travel0)  # fmt: skip
        finally:
            if belt_stopped and not rt.cell.estopped:
                with contextlib.suppress(Exception):
                    await rt.conveyor.start(mode="continuous", speed_m_s=top.speed_m_s)


async def pose_part(ctx: Context, opts: InspectOptions, plan: TopPlan, top: TopView,
                    draft: InspectionDraft, report: Any) -> Posed:  # fmt: skip
    """The part's pose (:class:`Posed`); its footprint radius goes into ``draft`` (the
    sort stage's obstacle box, and a failed inspection's reject)."""
    live = ctx.rt.live_index
    stored_h, grasp = pose_stage.geometry(live, draft.model)
    height = AIM_HEIGHT_M if stored_h is None else stored_h
    assert draft.found is not None  # the recognise stage found the part on the belt
    found = draft.found
    draft.radius = await asyncio.to_thread(pose_stage.footprint_radius, top.mask, ctx.camera,
                                           top.T_cam, found, ctx.surface_z + height)  # fmt: skip
    posed = Posed(None, "", stored_h, grasp, top.travel0)
    pose: ObjectPose | None = None
    err = ""
    if draft.decision == "recognized" and ctx.uncalibrated:
        err = ctx.uncalibrated
    elif draft.decision == "recognized":
        assert draft.model is not None  # recognised: a model
        try:
            pose = await pose_stage.estimate(
                ctx, pose_stage.top_candidate(top.res, draft.model), draft.model, top.T_cam,
                height, top.features[0] if top.features else None, top.mask,
            )  # fmt: skip
        except PoseFailed as exc:
            err = exc.detail
        if rests_on_too_little(pose):
            draft.stage = "second top view"
            report(0.8, "second top view (the pose rested on too little)")
            again = await secondtop.second_top_view(
                ctx, opts, draft.model, found, watch=draft.watch, first=pose, first_err=err,
                T_plan=plan.T_plan, top_mask=top.mask, T_cam_top=top.T_cam, height=height,
                travel0=top.travel0, gain=top.gain, mode=top.mode, speed_m_s=top.speed_m_s,
            )  # fmt: skip
            pose, err = again.pose, again.error
            if again.shot is not None:
                f2, T_cam2, record2 = again.shot
                draft.cams.append(T_cam2)
                draft.viewpoints = (*draft.viewpoints, 1)
                draft.views.append(record2)
                if again.used:
                    posed.travel = travel_of(f2, ctx.rt)
            posed.second = again.summary
    posed.pose, posed.error = pose, err
    return posed


def _publish_pose(ctx: Context, top: TopView, draft: InspectionDraft,
                  posed: Posed) -> ObjectPose | None:  # fmt: skip
    """The pose's public form into ``draft`` (at constant speed predicted along the belt to
    now: the pose returned is the predicted one), or the reason there is none."""
    height = AIM_HEIGHT_M if posed.stored_h is None else posed.stored_h
    pose = posed.pose
    if pose is None:
        if posed.error:
            draft.reason += f"; pose not computed: {posed.error}"
        return None
    pub = pose.public()
    pub["at_exposure"] = pose.T_base_obj.tolist()
    if top.mode == "continuous":
        # predicted from the exposure the pose is of; the travel reported counts from
        # the top view's (the truth's) exposure
        travel_now = belt_state(ctx.rt)[2]
        pose = predict_along_belt(pose, travel_now - posed.travel)
        pub.update(T_base_obj=pose.T_base_obj.tolist(),
                   position_m=[float(v) for v in pose.T_base_obj[:3, 3]],
                   predicted_travel_m=travel_now - top.travel0,
                   at_exposure_travel_m=posed.travel - top.travel0)  # fmt: skip
    pub.update(camera_model=ctx.source, belt_mode=top.mode, z_plane_m=ctx.surface_z + height,
               second_top_view=posed.second)  # fmt: skip
    draft.pose = pub
    return pose
