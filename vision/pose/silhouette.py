"""Answers of the pose judged by the object's outline: a trained region moved by an answer
against the current region.

A part whose features repeat round a circle (a flange's bolts) registers a turn off on as
many correspondences as it registers right; its outline (a side nozzle, a shaft) does not
fit there.  :func:`silhouette_overlap` maps a trained view's region through a horizontal
plane into the current camera by the answer's planar motion (the plane-induced homography
of Hartley and Zisserman [1]_, fitted to the region's grid so the lens distortion is
averaged over it) and scores the intersection over union with the current region, the best
over small shifts; :func:`choose_by_silhouette` picks among the answers of groups of
agreeing views by it.

References
----------
.. [1] R. Hartley and A. Zisserman, *Multiple View Geometry in Computer Vision*, 2nd ed.,
   Cambridge University Press, 2003, section 13.1 (homographies induced by a plane).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from vision.camera import PinholeCamera
from vision.pose.geometry import ObjectPose, PoseFailed, plane_points, sample_region

__all__ = [
    "SILHOUETTE_MIN_SHARE",
    "SILHOUETTE_SHIFT",
    "SILHOUETTE_TOLERANCE",
    "SilhouetteView",
    "choose_by_silhouette",
    "fixed_mask",
    "silhouette_overlap",
]

#: Groups of agreeing views whose answers overlap the current region (intersection over
#: union of the trained silhouette moved by the answer) within this much of the best group
#: fit the outline equally well; a group needs at least :data:`SILHOUETTE_MIN_SHARE` of the
#: leading group's correspondences to be considered.
SILHOUETTE_TOLERANCE = 0.02
SILHOUETTE_MIN_SHARE = 0.2
#: Largest shift of the moved trained region searched, as a share of the current region's
#: size (the answers' positions are a few millimetres off; a turn moves more).
SILHOUETTE_SHIFT = 0.04


@dataclass(frozen=True, eq=False)
class SilhouetteView:
    """A trained top view of the model whose region can be compared with the current one:
    its camera pose, the model frame as it saw it, and its region (``mask()``, decoded
    when first asked for: only the views nearest an answer's viewpoint are)."""

    T_base_cam_view: NDArray[np.float64]
    T_base_obj_taught: NDArray[np.float64]
    mask: Callable[[], NDArray[np.bool_] | None]


def fixed_mask(mask: NDArray[np.bool_] | None) -> Callable[[], NDArray[np.bool_] | None]:
    """The ``mask`` callable of a :class:`SilhouetteView` whose region is already decoded."""
    return lambda: mask


def silhouette_overlap(
    view_mask: NDArray[np.bool_],
    query_mask: NDArray[np.bool_],
    *,
    camera: PinholeCamera,
    T_base_cam_view: NDArray[np.float64],
    T_base_cam_now: NDArray[np.float64],
    T_delta: NDArray[np.float64],
    z_m: float,
) -> float:
    """Intersection over union of the current region ``query_mask`` and the trained
    region ``view_mask`` moved by the planar motion ``T_delta`` (taught to now).

    The trained region is mapped through the plane ``z = z_m``: back-projected from the
    trained camera, moved, projected into the current camera (a homography fitted to a
    grid of the region's pixels, so the lens distortion is averaged over it).  Parts of
    the outline at other heights shift by parallax between the two cameras (a few
    millimetres when the trained camera stood near where the current one stands relative
    to the object: the caller picks that view), and the answer's position is a few
    millimetres off; the overlap is therefore the best over small shifts
    (:data:`SILHOUETTE_SHIFT`).  What it measures is whether the outline's asymmetric
    parts (a side nozzle, a shaft) lie where the answer puts them: answers a turn apart
    differ there by far more.

    Parameters
    ----------
    view_mask, query_mask : ndarray of shape (H, W), bool
        The trained and the current region.
    camera : PinholeCamera
    T_base_cam_view, T_base_cam_now : ndarray of shape (4, 4)
        Camera poses of the trained view and of the current exposure.
    T_delta : ndarray of shape (4, 4)
        The planar motion of the object since it was taught, base frame.
    z_m : float
        Height of the plane the region is mapped through, metres.

    Returns
    -------
    float
        Intersection over union in [0, 1]; 0 for empty regions, ``nan`` when the plane
        cannot be back-projected from the trained camera.
    """
    vm = np.asarray(view_mask, dtype=bool)
    qm = np.asarray(query_mask, dtype=bool)
    if not vm.any() or not qm.any():
        return 0.0
    src = sample_region(vm, vm.shape, n=8)
    if len(src) < 4:
        return 0.0
    try:
        P = plane_points(src, camera, T_base_cam_view, z_m)
    except PoseFailed:
        return math.nan
    P = P @ np.asarray(T_delta, dtype=np.float64)[:3, :3].T + np.asarray(T_delta)[:3, 3]
    T_cam_base = np.linalg.inv(np.asarray(T_base_cam_now, dtype=np.float64))
    rvec, _ = cv2.Rodrigues(T_cam_base[:3, :3])
    dst, _ = cv2.projectPoints(
        P.reshape(-1, 1, 3), rvec, T_cam_base[:3, 3], camera.K,
        np.asarray(camera.dist, dtype=np.float64),
    )  # fmt: skip
    Hm, _ = cv2.findHomography(src.reshape(-1, 1, 2), dst.reshape(-1, 1, 2), 0)
    if Hm is None or not np.all(np.isfinite(Hm)):
        return math.nan
    # compared at full resolution in a window round the current region (half its size
    # again on each side, so a moved outline stays inside)
    ys, xs = np.nonzero(qm)
    pad = int(0.5 * max(xs.max() - xs.min(), ys.max() - ys.min())) + 2
    h, w = qm.shape
    x0, y0 = max(0, int(xs.min()) - pad), max(0, int(ys.min()) - pad)
    x1, y1 = min(w, int(xs.max()) + pad + 1), min(h, int(ys.max()) + pad + 1)
    shift = np.array([[1.0, 0.0, -x0], [0.0, 1.0, -y0], [0.0, 0.0, 1.0]])
    warped = cv2.warpPerspective(vm.astype(np.uint8), shift @ Hm, (x1 - x0, y1 - y0),
                                 flags=cv2.INTER_NEAREST) > 0  # fmt: skip
    small_q = qm[y0:y1, x0:x1]
    # Each answer's position carries the plane fit's few millimetres of error, which moves
    # a round outline as much as a turn moves a small asymmetric part of it: the overlap
    # is the best over shifts of up to SILHOUETTE_SHIFT of the region's size (the
    # intersection at every shift in one correlation; the areas do not change).
    r = max(2, round(SILHOUETTE_SHIFT * max(xs.max() - xs.min(), ys.max() - ys.min())))
    q_pad = cv2.copyMakeBorder(
        small_q.astype(np.float32), r, r, r, r, cv2.BORDER_CONSTANT, value=0.0
    )
    inter = float(cv2.matchTemplate(q_pad, warped.astype(np.float32), cv2.TM_CCORR).max())
    union = float(np.count_nonzero(warped)) + float(np.count_nonzero(small_q)) - inter
    return 0.0 if union <= 0 else inter / union


def choose_by_silhouette(
    ranked: Sequence[tuple[ObjectPose, int, int]],
    *,
    camera: PinholeCamera,
    T_base_cam_now: NDArray[np.float64],
    z_m: float,
    query_mask: NDArray[np.bool_] | None,
    silhouettes: list[SilhouetteView],
) -> tuple[tuple[dict[str, object], ...], int]:
    """Of the answers of groups of agreeing views, the one to fit: the first of those (with at least :data:`SILHOUETTE_MIN_SHARE` of the leading
    group's correspondences) whose silhouette overlap is within
    :data:`SILHOUETTE_TOLERANCE` of the best.

    The outline settles what the correspondences cannot: a part whose features repeat
    round a circle registers a sixth of a turn off on as many of them as it registers
    right, but its outline (a side nozzle) overlaps far less there; and a plane answer
    thrown far off by parallax or look-alike features does not fit the outline either.
    Answers a few millimetres apart fit it about equally (the shift search absorbs them),
    and there the correspondences' joint fit is the better judge.

    A group's answer (its first view's plane pose) puts the current camera somewhere
    relative to the object; the trained view taken from nearest that place (the object
    frame of its teach) sees the outline with the least parallax, and its region moved
    by the answer is compared with the current one (:func:`silhouette_overlap`).

    Parameters
    ----------
    ranked : sequence of (ObjectPose, int, int)
        Per group, most correspondences first: its answer (its first view's plane pose),
        its views and its correspondences.
    camera : PinholeCamera
    T_base_cam_now : ndarray of shape (4, 4)
        Camera pose of the current exposure.
    z_m : float
        Height of the plane the regions are mapped through, metres.
    query_mask : ndarray of shape (H, W), bool, or None
        The current region (None: the first group is chosen).
    silhouettes : list of SilhouetteView
        Taught top views whose regions the answers are judged by.

    Returns
    -------
    record : tuple of dict
        Per group: its answer's position and yaw, views, correspondences, overlap, and
        whether it was chosen.
    pick : int
        Index of the chosen group in ``ranked``.
    """
    cam_now = np.asarray(T_base_cam_now, dtype=np.float64)[:, 3]
    rel_views = [
        (np.linalg.inv(np.asarray(v.T_base_obj_taught, dtype=np.float64))
         @ np.asarray(v.T_base_cam_view, dtype=np.float64)[:, 3])[:3]
        for v in silhouettes
    ]  # fmt: skip
    ious: list[float | None] = []
    for lead, _views, _n in ranked:
        if query_mask is None or not silhouettes or len(ranked) == 1:
            ious.append(None)
            continue
        T_obj = lead.T_base_obj
        rel_now = (np.linalg.inv(T_obj) @ cam_now)[:3]
        near = sorted(
            range(len(silhouettes)), key=lambda i: float(np.linalg.norm(rel_views[i] - rel_now))
        )
        iou: float | None = None
        for i in near:
            mask = silhouettes[i].mask()
            if mask is None:
                continue
            v = silhouettes[i]
            iou = silhouette_overlap(
                mask, query_mask, camera=camera, T_base_cam_view=v.T_base_cam_view,
                T_base_cam_now=T_base_cam_now,
                T_delta=T_obj @ np.linalg.inv(np.asarray(v.T_base_obj_taught, dtype=np.float64)),
                z_m=z_m,
            )  # fmt: skip
            break
        ious.append(iou if iou is not None and math.isfinite(iou) else None)
    # The outline rules out answers it does not fit; among those it fits about equally
    # (a position a few millimetres off is absorbed by the shift search), the most
    # correspondences decide, as without it.
    lead_n = ranked[0][2]
    eligible = [i for i in range(len(ranked)) if ious[i] is not None
                and (i == 0 or ranked[i][2] >= SILHOUETTE_MIN_SHARE * lead_n)]  # fmt: skip
    pick = 0
    if ious[0] is not None and eligible:
        best_iou = max(float(ious[i] or 0.0) for i in eligible)
        pick = next(i for i in eligible if float(ious[i] or 0.0) >= best_iou - SILHOUETTE_TOLERANCE)
    record: tuple[dict[str, object], ...] = tuple(
        {
            "position_m": [float(v) for v in lead.T_base_obj[:3, 3]],
            "yaw_rad": float(lead.yaw_rad),
            "views": int(views),
            "correspondences": int(n),
            "silhouette_iou": None if iou is None else round(float(iou), 4),
            "chosen": i == pick,
        }
        for i, ((lead, views, n), iou) in enumerate(zip(ranked, ious, strict=True))
    )
    return record, pick
