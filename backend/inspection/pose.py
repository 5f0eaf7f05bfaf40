"""The pose stage: the part's pose from the trained top views that verify on the top view
(:func:`estimate`, :mod:`vision.pose`); when it rests on too little
(:func:`vision.pose.rests_on_too_little`) a second top view gives it
(:mod:`backend.inspection.secondtop`), or the part has no pose.  At constant speed the pose
is predicted along the belt to now."""

from __future__ import annotations

import asyncio
import functools
import math
from typing import Any

import numpy as np
from numpy.typing import NDArray
from sqlalchemy import select

from backend.db.models import TrainedView
from backend.inspection.context import Context, cam_pose
from vision.pose import (
    ObjectPose,
    PoseFailed,
    SilhouetteView,
    ViewMatch,
    estimate_pose_views,
    plane_points,
)
from vision.pose.structure import FeatureHeights, HeightCache, TaughtTopView
from vision.recognition.recognise import verify_view

__all__ = ["FEATURE_HEIGHTS", "estimate", "footprint_radius",
           "geometry", "geometry_source", "top_candidate", "warm_feature_heights"]  # fmt: skip


def geometry(live: Any, name: str | None) -> tuple[float | None, NDArray[np.float64] | None]:
    """Height and suction point of a recognised model, as stored with it (``height_m``,
    ``grasp_obj``: measured at teach time or entered by an engineer); ``(None, None)`` for
    an unknown object or a model without them.  Never the simulator's catalogue."""
    m = None if name is None else live.model_of_name(name)
    if m is None:
        return None, None
    g = None if m.grasp_obj is None else np.asarray(m.grasp_obj, dtype=np.float64)
    return m.height_m, g


def geometry_source(live: Any, name: str | None) -> str:
    """How a recognised model's height was stored: ``measured``, ``entered`` or ``""``."""
    m = None if name is None else live.model_of_name(name)
    return "" if m is None else str(getattr(m, "geometry_source", "") or "")


def footprint_radius(
    mask: NDArray[np.bool_],
    camera: Any,
    T_cam: NDArray[np.float64],
    centre: NDArray[np.float64],
    z_m: float,
) -> float:
    """Half-width of the object's region seen from the top, on the plane ``z_m`` about
    ``centre`` (its obstacle box for the approach), metres, plus 1 cm."""
    ys, xs = np.nonzero(mask)
    step = max(1, len(xs) // 2000)
    pts = plane_points(
        np.stack([xs[::step], ys[::step]], axis=1).astype(np.float64), camera, T_cam, z_m
    )
    return float(min(0.5, np.linalg.norm(pts[:, :2] - centre[:2], axis=1).max() + 0.01))


#: Most trained top views the pose is computed from (the recognised one and the others of
#: the model that verify best on the top view), and the fewest inliers a view needs.
POSE_MAX_VIEWS = 6
POSE_MIN_INLIERS = 6
#: Triangulated feature heights of the models' taught top views, per process (keyed by the
#: views' features and poses and the calibration, so a model taught again gets new ones).
FEATURE_HEIGHTS = HeightCache()


def top_candidate(res: Any, model: str) -> Any:
    """The recognition's candidate of ``model`` on the top view (viewpoint 1) with a
    homography: the trained view the pose starts from."""
    top = next((r for vp, r in zip(res.viewpoints, res.views, strict=True) if vp == 1), None)
    cand = (
        None
        if top is None
        else next((c for c in top.candidates if c.model == model and c.H is not None), None)
    )
    if cand is None or cand.viewpoint != 1:
        raise PoseFailed("the top view did not verify the recognised model (no homography)")
    return cand


async def estimate(
    ctx: Context, cand: Any, model: str, T_cam_now: NDArray[np.float64], height: float,
    query: Any = None, query_mask: NDArray[np.bool_] | None = None,
) -> ObjectPose:  # fmt: skip
    """The pose from the trained top view ``cand`` (the recognition's candidate on the top
    view; None: the model's top view that verifies best on ``query`` leads) and the model's
    other top views that verify on the top view's features ``query``
    (:func:`estimate_pose_views`; the top view's region ``query_mask`` judges answers that
    disagree by their silhouettes)."""
    live = ctx.rt.live_index

    def verify_others() -> tuple[Any, list[Any], list[int]]:
        with live.reading() as index:
            top_ids = [v.view_id for v in index.views_of(model, viewpoint=1)]
            if query is None:
                return cand, [], top_ids
            skip = None if cand is None else cand.view_id
            got = [verify_view(index, vid, query) for vid in top_ids if vid != skip]
        ok = sorted((c for c in got if c.H is not None and c.n_inliers >= POSE_MIN_INLIERS),
                    key=lambda c: (-c.n_inliers, c.view_id))  # fmt: skip
        lead = cand if cand is not None else (ok.pop(0) if ok else None)
        return lead, ok[: POSE_MAX_VIEWS - 1], top_ids

    cand, others, top_ids = await asyncio.to_thread(verify_others)
    if cand is None:
        raise PoseFailed(f"no trained top view of {model} verified on this view")
    cands = [cand, *others]
    async with ctx.rt.database.session() as session:
        rows = await session.execute(
            select(TrainedView.id, TrainedView.joints, TrainedView.yaw_rad, TrainedView.mask_png,
                   TrainedView.height, TrainedView.width)
            .where(TrainedView.id.in_({c.view_id for c in cands} | set(top_ids)))
        )  # fmt: skip
        stored = {int(vid): (j, y, m, (h, w)) for vid, j, y, m, h, w in rows.all()}
    if stored.get(cand.view_id, (None,))[0] is None:
        raise PoseFailed(f"trained view {cand.view_id} has no camera pose (uploaded, not taught)")
    from backend.recognition.images import mask_from_png

    def heights_of_inliers() -> dict[int, NDArray[np.float64]]:
        # the heights of each candidate's inlier features, looked up by their trained pixels
        fh, present = feature_heights(ctx, model, height, {v: (j, y) for v, (j, y, _m, _s)
                                                             in stored.items()})  # fmt: skip
        return {
            c.view_id: fh.of(c.view_id, c.inlier_xy[:, :2], present[c.view_id].features.keypoints.xy)
            for c in cands if c.inlier_xy is not None and c.view_id in present
        }  # fmt: skip

    known = await asyncio.to_thread(heights_of_inliers)
    matches = []
    for c in cands:
        joints, yaw, mask_png, shape = stored.get(c.view_id, (None, 0.0, None, (0, 0)))
        if joints is None or c.inlier_xy is None:
            continue  # deleted meanwhile, or uploaded without a camera pose
        matches.append(ViewMatch(
            c.H, c.inlier_xy, cam_pose(joints, ctx.T_ee_cam), taught_at(ctx, yaw),
            None if mask_png is None else mask_from_png(mask_png), shape, known.get(c.view_id),
        ))  # fmt: skip
    # Every taught top view of the model with a region judges answers that disagree by
    # their silhouettes (the region decoded only for the views nearest an answer's).
    silhouettes = [
        SilhouetteView(cam_pose(joints, ctx.T_ee_cam), taught_at(ctx, yaw),
                       functools.cache(functools.partial(mask_from_png, mask_png)))
        for vid, (joints, yaw, mask_png, _shape) in sorted(stored.items())
        if joints is not None and mask_png is not None
    ]  # fmt: skip
    return await asyncio.to_thread(
        estimate_pose_views, matches, camera=ctx.camera, T_base_cam_now=T_cam_now,
        z_plane_m=ctx.surface_z + height, z_floor_m=ctx.surface_z, query_mask=query_mask,
        silhouettes=silhouettes,
    )  # fmt: skip


def taught_at(ctx: Context, yaw: float) -> NDArray[np.float64]:
    """The model frame as a teach saw it: the station, turned by the teach's yaw."""
    T = np.eye(4)
    co, si = math.cos(yaw), math.sin(yaw)
    T[:2, :2] = [[co, -si], [si, co]]
    T[:3, 3] = ctx.station
    return T


def feature_heights(
    ctx: Context, model: str, height: float, poses: dict[int, tuple[Any, float]]
) -> tuple[FeatureHeights, dict[int, Any]]:
    """The triangulated heights of ``model``'s taught top views (:data:`FEATURE_HEIGHTS`:
    computed once per set of views and calibration) and the index's views by id; ``poses``
    gives each view's stored joints and teach yaw (views without joints were uploaded and
    take no part).  Runs in a worker thread."""
    live = ctx.rt.live_index
    with live.reading() as index:
        present = {v.view_id: v for v in index.views_of(model, viewpoint=1)}
    taught = [
        TaughtTopView(vid, present[vid].features, cam_pose(j, ctx.T_ee_cam), taught_at(ctx, y))
        for vid, (j, y) in sorted(poses.items()) if j is not None and vid in present
    ]  # fmt: skip
    fh = FEATURE_HEIGHTS.get(taught, camera=ctx.camera, z_floor_m=ctx.surface_z,
                             z_top_m=ctx.surface_z + height)  # fmt: skip
    return fh, present


async def warm_feature_heights(ctx: Context) -> int:
    """Triangulate every model's taught top views before the first inspection needs them
    (up to a second or two per model for the wheels on this machine's cores); returns the
    models done.  A model without a stored height is skipped (its pose is not computed)."""
    models = [m for m in ctx.rt.live_index.models().values() if m.height_m is not None]
    if not models:
        return 0
    async with ctx.rt.database.session() as session:
        rows = await session.execute(
            select(TrainedView.model_id, TrainedView.id, TrainedView.joints, TrainedView.yaw_rad)
            .where(TrainedView.model_id.in_([m.id for m in models]), TrainedView.viewpoint == 1)
        )  # fmt: skip
        poses: dict[int, dict[int, tuple[Any, float]]] = {}
        for mid, vid, j, y in rows.all():
            poses.setdefault(int(mid), {})[int(vid)] = (j, float(y))
    done = 0
    for m in models:
        if poses.get(m.id) and m.height_m is not None:  # (the list holds only those)
            await asyncio.to_thread(feature_heights, ctx, m.name, float(m.height_m), poses[m.id])
            done += 1
    return done
