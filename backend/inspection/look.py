"""Looking at the part: the top view's region when there is no background
(:class:`WholeImage`), and the side viewpoints planned where the top view found the part
(:func:`side_view`; at constant speed where the belt will have carried it,
:func:`carried`), each with the region of its image where the part can be."""

from __future__ import annotations

import asyncio
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from backend.inspection.context import Context, belt_state, cam_pose, travel_of
from backend.inspection.errors import CarriedAway
from backend.inspection.find import add_look
from backend.inspection.stopwatch import Stopwatch
from backend.planning import AIM_HEIGHT_M
from robot.viewpoints import VIEW_NAMES, plan_viewpoints
from vision.segmentation.roi import SideRoi, side_roi

__all__ = ["WHOLE_IMAGE_NOTE", "SideView", "WholeImage", "carried", "carried_point",
           "look_with_region", "plan_view", "side_view"]  # fmt: skip

#: What a result says when the top view had no empty-belt background to segment against.
WHOLE_IMAGE_NOTE = "recognised on the whole image (no empty-belt background: no teach on this cell)"


@dataclass(frozen=True, eq=False)
class WholeImage:
    """The top view's region when there is no background to segment against: every pixel."""

    mask: NDArray[np.bool_]
    method: str = WHOLE_IMAGE_NOTE


def carried_point(found: NDArray[np.float64], ahead_m: float, end_y_m: float,
                  vp: int) -> NDArray[np.float64]:  # fmt: skip
    """Where a side view (viewpoint ``vp``) looks for an object found at ``found`` in the
    top view, carried ``ahead_m`` along the belt since (its travel since the top view's
    exposure and during the move); :class:`CarriedAway` past the belt's end (``end_y_m``):
    the object has left the belt there (the simulator's belt brings it round to its start),
    so no view of it can be planned from the travel, and a point metres beyond the arm's
    reach would only fail the viewpoint planner with a workspace error."""
    point = np.asarray(found, dtype=np.float64) + np.array([0.0, float(ahead_m), 0.0])
    if not math.isfinite(float(ahead_m)) or point[1] > end_y_m:
        raise CarriedAway(
            f"viewpoint {vp}: the belt carried the object {float(ahead_m):.2f} m on since the "
            f"top view, past the belt's end (y {end_y_m:g} m): the views took too long"
        )
    return point


@dataclass(frozen=True, eq=False)
class SideView:
    """A side viewpoint visited: the frame, its camera pose, the query's region and the
    notes for the inspection's reason."""

    frame: Any
    T_base_cam: NDArray[np.float64]
    roi: SideRoi
    notes: tuple[str, ...]


async def look_with_region(ctx: Context, q: NDArray[np.float64], *, watch: Stopwatch,
                           top_mask: NDArray[np.bool_], T_cam_top: NDArray[np.float64],
                           height_m: float, travel0: float | None, speed: float | None,
                           **roi_options: Any) -> tuple[Any, NDArray[np.float64], SideRoi]:  # fmt: skip
    """Visit joints ``q``; the frame, its camera pose and the region of its image where the
    object found in the top view (``top_mask`` seen from ``T_cam_top``) can be
    (:func:`vision.segmentation.roi.side_roi`, up to ``height_m``, with ``roi_options``; with
    ``travel0`` -- the belt's travel at the top view's exposure, constant speed -- moved by
    the belt's travel since).  On ``watch``: the look as the cell times it (``move``,
    ``settle``, ``acquire``), the region as ``segment``."""
    with watch.pause():
        f = await ctx.rt.cell.look(q, speed=speed)
    add_look(watch, f)
    T_cam = cam_pose(f.robot_state.q, ctx.T_ee_cam)
    moved = None if travel0 is None else np.array([0.0, travel_of(f, ctx.rt) - travel0, 0.0])
    with watch.stage("segment"):
        roi = await asyncio.to_thread(
            side_roi, top_mask, camera=ctx.camera, T_base_cam_top=T_cam_top,
            T_base_cam_side=T_cam, surface_z_m=ctx.surface_z, height_m=height_m,
            image_shape=f.rgb.shape[:2], moved_m=moved, **roi_options,
        )  # fmt: skip
    return f, T_cam, roi


async def plan_view(point: NDArray[np.float64], vp: int, T_plan: NDArray[np.float64],
                    watch: Stopwatch, **options: Any) -> Any:  # fmt: skip
    """Viewpoint ``vp`` planned at ``point`` (:func:`plan_viewpoints`, aimed at
    :data:`~backend.planning.AIM_HEIGHT_M`), timed as ``plan``."""
    with watch.stage("plan"):
        return await asyncio.to_thread(plan_viewpoints, point, T_ee_cam=T_plan,
                                       views=(VIEW_NAMES[vp - 1],), object_height_m=AIM_HEIGHT_M,
                                       **options)  # fmt: skip


async def side_view(ctx: Context, vp: int, point: NDArray[np.float64], *, watch: Stopwatch,
                    T_plan: NDArray[np.float64], top_mask: NDArray[np.bool_],
                    T_cam_top: NDArray[np.float64], height_m: float, travel0: float | None,
                    speed: float | None) -> SideView:  # fmt: skip
    """Viewpoint ``vp`` (2 or 3) planned at ``point`` (:func:`plan_view`), visited, and the
    region of its image where the object can be (:func:`look_with_region`).  A region
    that cannot be made is the whole frame, noted."""
    plan = await plan_view(point, vp, T_plan, watch)
    notes = [f"viewpoint {vp}: {plan.views[0].reason}"] if plan.views[0].reason else []
    f, T_cam, roi = await look_with_region(
        ctx, plan.views[0].q, watch=watch, top_mask=top_mask, T_cam_top=T_cam_top,
        height_m=height_m, travel0=travel0, speed=speed,
    )  # fmt: skip
    if roi.mask is None:
        notes.append(f"viewpoint {vp}: {roi.reason}")
    return SideView(f, T_cam, roi, tuple(notes))


def carried(ctx: Context, found: NDArray[np.float64], travel0: float, speed_m_s: float,
             vp: int) -> NDArray[np.float64]:  # fmt: skip
    """Where to plan viewpoint ``vp`` of the object found at ``found`` in the top view (belt
    travel ``travel0`` then) at constant speed: where the belt will have carried it 1.5 s
    from now (:func:`carried_point`)."""
    ahead = belt_state(ctx.rt)[2] - travel0 + 1.5 * speed_m_s
    return carried_point(found, ahead, ctx.belt_end_y_m, vp)
