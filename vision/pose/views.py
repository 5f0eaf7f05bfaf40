"""The object's pose from several trained top views at once, judged by the outline.

One view cannot tell a feature's height from the object's shift when the two cameras
moved parallel to the belt (the parallax is then a shift too), so a part whose features
lie far below its height (a valve block's top face, tens of millimetres under its
solenoid's cap) keeps a pose millimetres off.  :func:`estimate_pose_views` therefore takes
the model's other trained top views that verify on the current one as well (taught at
other object yaws and camera rolls, they see the parallax in other directions), keeps the
views whose answers agree (a view registered on the wrong features, a flange's bolt circle
a sixth of a turn off, is outvoted) and fits their correspondences together: one motion,
every feature at its own height on its own view's ray
(:func:`vision.pose.parallax.fit_motion`).  Where the views that agree on a wrong turn hold
the most correspondences (each of the flange's bolts looks like the next), the answers
are also judged by the outline: the trained region nearest in viewpoint, moved by each
answer, against the current region (:func:`silhouette_overlap`).

The heights need not be guessed per inspection: they are the model's.  The taught top
views were taken from known camera poses with the object in known frames, so features seen
in several of them are triangulated once (:mod:`vision.pose.structure`) and the fit holds
each such feature near its triangulated height (:data:`~vision.pose.parallax.W_TRIANGULATED`).
Features that two taught views do not match to each other are often matched by two or more
of the agreeing views: where their trained rays meet in the model's frame is the feature's
place (the midpoint triangulation of Hartley and Zisserman [1]_), and the fit holds it there
as firmly as the rays' angle fixes it (:func:`_rays_met`).  Only the features placed neither
way keep the weak pull towards the top face.

References
----------
.. [1] R. Hartley and A. Zisserman, *Multiple View Geometry in Computer Vision*, 2nd ed.,
   Cambridge University Press, 2003, section 12.2.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from vision.camera import PinholeCamera
from vision.pose.geometry import (
    ObjectPose,
    PoseFailed,
    closest_points,
    object_rays,
    pose_apart,
    yaw_of,
)
from vision.pose.parallax import (
    MIN_PARALLAX_POINTS,
    W_TRIANGULATED,
    Group,
    estimate_pose,
    fit_motion,
)
from vision.pose.silhouette import SilhouetteView, choose_by_silhouette, fixed_mask

__all__ = ["ViewMatch", "estimate_pose_views"]


@dataclass(frozen=True, eq=False)
class ViewMatch:
    """One trained top view of the recognised model verified on the current top view.

    Attributes
    ----------
    H : ndarray of shape (3, 3)
        Trained-view pixels to current pixels.
    inlier_xy : ndarray of shape (N, 4)
        The correspondences behind ``H`` (trained ``x, y``, current ``x, y``, pixels).
    T_base_cam_view : ndarray of shape (4, 4)
        The camera pose the view was taken from.
    T_base_obj_taught : ndarray of shape (4, 4)
        The model frame as the view saw it (the station, turned by the view's yaw).
    view_mask : ndarray of shape (H, W), bool, or None
    view_shape : (int, int)
    heights : ndarray of shape (N,) or None
        Triangulated base-frame heights of ``inlier_xy``'s trained features (``nan`` where
        unknown; :mod:`vision.pose.structure`), or ``None``.
    """

    H: NDArray[np.float64]
    inlier_xy: NDArray[np.float64]
    T_base_cam_view: NDArray[np.float64]
    T_base_obj_taught: NDArray[np.float64]
    view_mask: NDArray[np.bool_] | None
    view_shape: tuple[int, int]
    heights: NDArray[np.float64] | None = None


#: Two trained views' plane poses agree when within this distance and turn of each other
#: (the plane answer alone is millimetres off for parts with features below the top face; a
#: view registered on the wrong features, the pipe flange's bolt circle a sixth of a turn
#: off or the valve block on a handful of look-alike corners, is tens of millimetres or
#: degrees away).
AGREE_M = 0.008
AGREE_YAW_RAD = math.radians(4.0)


def estimate_pose_views(
    matches: list[ViewMatch],
    *,
    camera: PinholeCamera,
    T_base_cam_now: NDArray[np.float64],
    z_plane_m: float,
    z_floor_m: float,
    query_mask: NDArray[np.bool_] | None = None,
    silhouettes: list[SilhouetteView] | None = None,
) -> ObjectPose:
    """The object's pose from several trained top views verified on the current one.

    One view's homography can rest on a handful of inliers (a plain part) or on the wrong
    features (a part with a repeating pattern); several views taught at other yaws and
    camera rolls give independent answers.  Each view's plane answer is computed
    (:func:`estimate_pose` without refinement); the views whose answers agree within
    :data:`AGREE_M` / :data:`AGREE_YAW_RAD` of one another form groups, and the group with
    the most correspondences wins (ties: the earlier view, so list the best-scored view
    first).  The winning group's correspondences are then fitted together with each
    feature at its own height (:func:`refine_with_parallax`'s model, one motion for all
    views); with fewer than :data:`MIN_PARALLAX_POINTS` of them, or a failed fit, the
    first view of the group gives the answer alone (:func:`estimate_pose`).

    With ``query_mask`` (the current top view's region) and more than one group, the
    groups are also judged by their silhouettes (:func:`~vision.pose.silhouette.choose_by_silhouette`): the trained
    region of ``silhouettes`` (every taught top view of the model; default: the matches'
    own masks) nearest each answer's viewpoint, moved by that answer, against the current
    region.  A part whose features repeat round a circle (the pipe flange's bolts) can
    register a sixth of a turn off on as many correspondences as it registers right; its
    outline (the side nozzle) cannot.  Every group considered is recorded in
    :attr:`ObjectPose.hypotheses`.

    Parameters
    ----------
    matches : list of ViewMatch
        The trained top views verified on the current one, best-scored first.
    camera : PinholeCamera
    T_base_cam_now : ndarray of shape (4, 4)
        Camera pose of the current exposure.
    z_plane_m, z_floor_m : float
        Heights of the object's top face and of the belt surface, metres.
    query_mask : ndarray of shape (H, W), bool, optional
        The object's region in the current view.
    silhouettes : list of SilhouetteView, optional
        Taught top views whose regions the answers are judged by.

    Returns
    -------
    ObjectPose
        ``method="parallax"`` with ``views`` the views fitted, or the lead view's own
        answer (:func:`~vision.pose.parallax.estimate_pose`).

    Raises
    ------
    PoseFailed
        No view gives a plane answer.
    """
    if not matches:
        raise PoseFailed("no verified trained top view to compute the pose from")
    planes: list[tuple[ViewMatch, ObjectPose]] = []
    first_error: PoseFailed | None = None
    for m in matches:
        try:
            p = estimate_pose(
                m.H, camera=camera, T_base_cam_view=m.T_base_cam_view,
                T_base_cam_now=T_base_cam_now, T_base_obj_taught=m.T_base_obj_taught,
                z_plane_m=z_plane_m, view_mask=m.view_mask, view_shape=m.view_shape,
            )  # fmt: skip
        except PoseFailed as exc:
            first_error = first_error or exc
            continue
        planes.append((m, p))
    if not planes:
        assert first_error is not None
        raise first_error

    def agree(a: ObjectPose, b: ObjectPose) -> bool:
        d, dyaw = pose_apart(a, b)
        return d <= AGREE_M and dyaw <= AGREE_YAW_RAD

    groups_seen: list[tuple[list[tuple[ViewMatch, ObjectPose]], int]] = []
    for _seed_m, seed in planes:
        group = [(m, p) for m, p in planes if agree(seed, p)]
        members = {id(m) for m, _ in group}
        if any({id(m) for m, _ in g} == members for g, _ in groups_seen):
            continue
        groups_seen.append((group, sum(len(m.inlier_xy) for m, _ in group)))
    # the most correspondences first (ties: the earlier view)
    order = sorted(range(len(groups_seen)), key=lambda i: -groups_seen[i][1])
    ranked = [groups_seen[i] for i in order]
    hyps, pick = choose_by_silhouette(
        [(g[0][1], len(g), n) for g, n in ranked], camera=camera, T_base_cam_now=T_base_cam_now,
        z_m=0.5 * (z_plane_m + z_floor_m), query_mask=query_mask,
        silhouettes=silhouettes if silhouettes is not None else [
            SilhouetteView(m.T_base_cam_view, m.T_base_obj_taught, fixed_mask(m.view_mask))
            for m in matches if m.view_mask is not None
        ],
    )  # fmt: skip
    best, best_n = ranked[pick]
    lead_m, lead = best[0]

    def single() -> ObjectPose:
        return estimate_pose(
            lead_m.H, camera=camera, T_base_cam_view=lead_m.T_base_cam_view,
            T_base_cam_now=T_base_cam_now, T_base_obj_taught=lead_m.T_base_obj_taught,
            z_plane_m=z_plane_m, view_mask=lead_m.view_mask, view_shape=lead_m.view_shape,
            inlier_xy=lead_m.inlier_xy, z_floor_m=z_floor_m, heights=lead_m.heights,
        )  # fmt: skip

    if len(best) == 1 or best_n < MIN_PARALLAX_POINTS:
        return dataclasses.replace(single(), hypotheses=hyps)
    T_ref = np.asarray(lead_m.T_base_obj_taught, dtype=np.float64)
    views = [m for m, _p in best]
    met = _rays_met(views, camera=camera, z_floor_m=z_floor_m, z_top_m=z_plane_m)
    groups: list[Group] = []
    for m, (z_met, w_met) in zip(views, met, strict=True):
        pairs = np.asarray(m.inlier_xy, dtype=np.float64).reshape(-1, 4)
        if len(pairs) and np.all(np.isfinite(pairs)):
            known = None if m.heights is None else np.asarray(m.heights, dtype=np.float64)
            if known is None or len(known) != len(pairs):
                known = np.full(len(pairs), np.nan)
            # the model's own triangulation first (several taught pairs agreed on it)
            taught = np.isfinite(known)
            A = T_ref @ np.linalg.inv(np.asarray(m.T_base_obj_taught, dtype=np.float64))
            groups.append((pairs, m.T_base_cam_view, A, np.where(taught, known, z_met),
                           np.where(taught, W_TRIANGULATED, w_met)))  # fmt: skip
    T_delta0 = lead.T_base_obj @ np.linalg.inv(T_ref)
    refined = fit_motion(groups, camera=camera, T_base_cam_now=T_base_cam_now, T_delta0=T_delta0,
                      z_floor_m=z_floor_m, z_top_m=z_plane_m)  # fmt: skip
    if refined is None:
        return dataclasses.replace(single(), hypotheses=hyps)
    T_delta, reproj, n_used, n_tri = refined
    T = T_delta @ T_ref
    return ObjectPose(T, yaw_of(T), lead.residual_m, n_used, "parallax", reproj, len(groups), hyps,
                      n_tri)  # fmt: skip


#: Correspondences of two agreeing trained views share a current keypoint when their
#: current points lie within this distance, pixels (one detection gives one point).
SAME_KEYPOINT_PX = 0.5
#: Their trained rays meet at a point of the part when they pass within this distance of
#: each other in the model's frame, pixels at the point's depth.
RAYS_MEET_PX = 2.0


def _rays_met(
    views: list[ViewMatch], *, camera: PinholeCamera, z_floor_m: float, z_top_m: float
) -> list[tuple[NDArray[np.float64], NDArray[np.float64]]]:
    """Per view of an agreeing group, per correspondence: the base-frame height where its
    trained ray meets another view's ray to the same current keypoint (``nan`` where none
    does), and how firmly that fixes it, pixels per metre: a pixel along either ray moves
    the meeting point by ``depth / (f sin angle)``, so rays a few degrees apart fix the
    height to millimetres, not to the teach's fraction of one.

    The views were taught at other yaws and camera rolls, so a point of the part is seen
    along trained rays that cross in the model's frame, and where they cross is its place:
    the current view triangulates the features it matched twice, as the taught views do
    for the features they matched to each other (:mod:`vision.pose.structure`, which
    finds few of the pipe flange's).  A highlight on shiny steel or the outline of a round
    surface stays with the lights or the camera while the part turns, and its rays pass
    each other by."""
    from scipy.spatial import cKDTree

    f = float(camera.K[0, 0])
    origins, dirs, cur, owner, index = [], [], [], [], []
    for v, m in enumerate(views):
        pairs = np.asarray(m.inlier_xy, dtype=np.float64).reshape(-1, 4)
        if not len(pairs):
            continue
        centre, d, _ = object_rays(pairs[:, :2], camera, m.T_base_cam_view, m.T_base_obj_taught)
        dirs.append(d)
        # the model frames are level and differ by a turn about z, so a height in the
        # model's frame moves to the base by the view's station height
        lift = np.array([0.0, 0.0, float(np.asarray(m.T_base_obj_taught)[2, 3])])
        origins.append(np.broadcast_to(centre + lift, d.shape))
        cur.append(pairs[:, 2:])
        owner.append(np.full(len(pairs), v))
        index.append(np.arange(len(pairs)))
    out = [(np.full(len(m.inlier_xy), np.nan), np.zeros(len(m.inlier_xy))) for m in views]
    if not dirs:
        return out
    o, d, c = np.concatenate(origins), np.concatenate(dirs), np.concatenate(cur)
    who, idx = np.concatenate(owner), np.concatenate(index)
    # pairs of correspondences to one current keypoint from two views (a tree: memory and
    # time grow with the pairs found, not with the square of the correspondences)
    near = cKDTree(c).query_pairs(SAME_KEYPOINT_PX, output_type="ndarray").reshape(-1, 2)
    near = near[who[near[:, 0]] != who[near[:, 1]]]
    a, b = np.r_[near[:, 0], near[:, 1]], np.r_[near[:, 1], near[:, 0]]
    Pa, Pb, s, t, sin2 = closest_points(o[a], d[a], o[b], d[b])
    ok = sin2 > 1e-6
    depth = np.minimum(s, t)
    gap_px = f * np.linalg.norm(Pa - Pb, axis=1) / np.where(depth > 0, depth, 1.0)
    z = 0.5 * (Pa[:, 2] + Pb[:, 2])
    ok &= (depth > 0) & (gap_px <= RAYS_MEET_PX) & (z >= z_floor_m - 0.003) & (z <= z_top_m + 0.003)
    firm = f * np.sqrt(sin2) / np.where(depth > 0, depth, 1.0)
    z_met, w_met = np.full(len(d), np.nan), np.zeros(len(d))
    # per correspondence, its firmest meeting (written last)
    for k in np.flatnonzero(ok)[np.argsort(firm[ok], kind="stable")]:
        z_met[a[k]], w_met[a[k]] = z[k], firm[k]
    for v in range(len(views)):
        zs, ws = out[v]
        zs[idx[who == v]], ws[idx[who == v]] = z_met[who == v], w_met[who == v]
    return out
