"""The object's pose from a trained top view's homography, refined by parallax.

Recognition maps the best trained top view onto the current one with a plane homography
``H`` (``x_now ~ H @ x_view``, chapter eq. 12's planar case).  The trained view was taken
from a known camera pose (its stored joints, through ``T_base_ee(q) @ T_ee_cam``, chapter
eq. 20) with the object in the model's frame (where it sat when taught: the station point,
turned by the view's yaw), and the current view from the camera pose at exposure.  Points
of the object's top face seen in the trained view are

1. undistorted with the active intrinsics and back-projected onto the horizontal plane of
   the top face (belt surface plus the model's height) from the trained camera,
2. mapped by ``H`` into the current image, undistorted and back-projected onto the same
   plane from the current camera,

and the planar rigid motion between the two point sets (least squares, Kabsch/Umeyama
without scale, :func:`vision.pose.geometry.plane_motion`) is the object's motion since it
was taught: ``T_base_obj = T_delta @ T_base_obj_taught``, its yaw the rotation about the
belt normal.  The residual of the fit (RMS, metres) says how well the points agree.

That plane is only right for a flat top.  The camera of the top view sits off the
station's vertical (the 5-DOF wrist, the camera beside the flange) and moves on a circle
with the camera roll, and the object turns under it, so the trained and the current camera
see the object from places up to about 100 mm apart: features below the top face (a
wheel's spokes and hub, a bracket's base plate) shift by parallax, ``H`` averages them into
one plane's map, and back-projecting at the top face's height puts the pose millimetres
off.  With the verification's inlier correspondences
(:attr:`vision.recognition.recognise.Candidate.inlier_xy`) the motion is therefore refined
by :func:`refine_with_parallax`: the planar motion and every feature's own height (on its
trained viewing ray, bounded between the belt and the top face) minimising the
reprojection error in the current image (a sparse bundle adjustment with the structure
restricted to one height per point, Triggs et al. [1]_), started from the plane's answer.

References
----------
.. [1] B. Triggs, P. McLauchlan, R. Hartley and A. Fitzgibbon, "Bundle adjustment - a
   modern synthesis", in *Vision Algorithms: Theory and Practice*, LNCS 1883, Springer,
   2000, 298-372.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
from numpy.typing import NDArray

from vision.camera import PinholeCamera
from vision.pose.geometry import (
    ObjectPose,
    PoseFailed,
    plane_motion,
    sample_region,
    viewing_rays,
    yaw_of,
)
from vision.recognition.recognise import REPROJ_PX

__all__ = [
    "MAX_RESIDUAL_M",
    "MIN_PARALLAX_POINTS",
    "Group",
    "estimate_pose",
    "fit_motion",
    "refine_with_parallax",
]

#: Largest residual of the planar fit accepted, metres.
MAX_RESIDUAL_M = 0.01
#: Fewest inlier correspondences the parallax refinement uses (below: the plane's answer;
#: each feature adds one unknown, its height, to the three of the motion).
MIN_PARALLAX_POINTS = 8
#: Most correspondences used (the best spread subset beyond it would gain little).
MAX_PARALLAX_POINTS = 400
#: The refinement may move the plane's answer at most this far, metres, and turn it at most
#: :data:`MAX_REFINE_YAW_RAD`: a larger change means a failed fit, not a better one.
MAX_REFINE_SHIFT_M = 0.02
MAX_REFINE_YAW_RAD = math.radians(5.0)
#: Pixels beyond which a correspondence counts as an outlier in the robust loss (the scale
#: of the soft-L1 loss): about the median distance of a well-matched part's inliers from
#: where the true motion puts them.
PARALLAX_F_SCALE_PX = 0.75
#: A correspondence the first fit leaves further than this from its prediction, pixels, is
#: dropped and the fit run again: the verification's own inlier threshold
#: (:data:`vision.recognition.recognise.REPROJ_PX`), now with every feature at its height.
REJECT_PX = REPROJ_PX


def estimate_pose(
    H: NDArray[np.float64],
    *,
    camera: PinholeCamera,
    T_base_cam_view: NDArray[np.float64],
    T_base_cam_now: NDArray[np.float64],
    T_base_obj_taught: NDArray[np.float64],
    z_plane_m: float,
    view_mask: NDArray[np.bool_] | None,
    view_shape: tuple[int, int],
    inlier_xy: NDArray[np.float64] | None = None,
    z_floor_m: float | None = None,
    heights: NDArray[np.float64] | None = None,
) -> ObjectPose:
    """The object's pose now from the homography of the trained top view (module docstring).

    Parameters
    ----------
    H : ndarray of shape (3, 3)
        Trained-view pixels to current pixels.
    camera : PinholeCamera
        Active intrinsics (or the nominal camera).
    T_base_cam_view, T_base_cam_now : ndarray of shape (4, 4)
        Camera poses of the trained view and of the current exposure.
    T_base_obj_taught : ndarray of shape (4, 4)
        The model frame as the trained view saw it.
    z_plane_m : float
        Height of the object's top face in the base frame, metres.
    view_mask : ndarray of shape (H, W), bool, or None
        The object's region in the trained view (points are sampled inside it).
    view_shape : (int, int)
        Trained image height and width.
    inlier_xy : ndarray of shape (N, 4), optional
        The correspondences behind ``H`` (trained ``x, y``, current ``x, y``, pixels): with
        at least :data:`MIN_PARALLAX_POINTS` of them and ``z_floor_m`` the plane's answer is
        refined by :func:`refine_with_parallax`.
    z_floor_m : float, optional
        Lowest height a feature can have (the belt surface), metres.
    heights : ndarray of shape (N,), optional
        Base-frame heights of ``inlier_xy``'s trained features triangulated from the taught
        views (:mod:`vision.pose.structure`; ``nan`` where unknown): the refinement
        holds those features near them.

    Raises
    ------
    PoseFailed
        Degenerate homography, too few points, or a residual above :data:`MAX_RESIDUAL_M`.
    """
    Hm = np.asarray(H, dtype=np.float64)
    if Hm.shape != (3, 3) or not np.all(np.isfinite(Hm)) or abs(np.linalg.det(Hm)) < 1e-12:
        raise PoseFailed("the recognition gave no usable homography for the top view")
    src = sample_region(view_mask, view_shape)
    if len(src) < 4:
        raise PoseFailed(f"only {len(src)} points inside the trained view's mask")
    dst = cv2.perspectiveTransform(src.reshape(-1, 1, 2), Hm).reshape(-1, 2)
    src_px: np.ndarray = np.asarray(src, dtype=np.float64)
    dst_px: np.ndarray = np.asarray(dst, dtype=np.float64)
    R2, t2, resid = plane_motion(src_px, dst_px, camera, T_base_cam_view, T_base_cam_now, z_plane_m)
    if resid > MAX_RESIDUAL_M:
        raise PoseFailed(
            f"the top view's points disagree by {resid * 1e3:.1f} mm RMS after the planar fit "
            f"(limit {MAX_RESIDUAL_M * 1e3:.0f} mm): the homography is not a rigid motion"
        )
    T_delta = np.eye(4)
    T_delta[:2, :2] = R2
    T_delta[:2, 3] = t2
    method, n, reproj, n_tri = "plane", len(src), None, 0
    if inlier_xy is not None and z_floor_m is not None:
        pairs = np.asarray(inlier_xy, dtype=np.float64).reshape(-1, 4)
        if len(pairs) >= MIN_PARALLAX_POINTS and np.all(np.isfinite(pairs)):
            refined = fit_motion(
                [(pairs, T_base_cam_view, np.eye(4), heights, None)], camera=camera,
                T_base_cam_now=T_base_cam_now, T_delta0=T_delta, z_floor_m=z_floor_m,
                z_top_m=z_plane_m,
            )  # fmt: skip
            if refined is not None:
                T_delta, reproj, n, n_tri = refined
                method = "parallax"
    T = T_delta @ np.asarray(T_base_obj_taught, dtype=np.float64)
    return ObjectPose(T, yaw_of(T), resid, n, method, reproj, triangulated=n_tri)


def refine_with_parallax(
    inlier_xy: NDArray[np.float64],
    *,
    camera: PinholeCamera,
    T_base_cam_view: NDArray[np.float64],
    T_base_cam_now: NDArray[np.float64],
    T_delta0: NDArray[np.float64],
    z_floor_m: float,
    z_top_m: float,
    heights: NDArray[np.float64] | None = None,
) -> tuple[NDArray[np.float64], float] | None:
    """The planar motion ``T_delta`` (taught to now, base frame) fitted to correspondences
    with each feature at its own height (module docstring); ``None`` when the fit fails.

    Unknowns: the motion's yaw and translation and, per correspondence, the height ``z_i``
    of the feature on its trained viewing ray, bounded to ``[z_floor_m, z_top_m]`` (1 mm
    slack each side).  Residuals: the feature moved by the motion and projected into the
    current camera against where it was seen, in undistorted pixels (robust soft-L1 loss,
    :data:`PARALLAX_F_SCALE_PX`), and a pull of every height towards a prior.  Where the
    taught views triangulated the feature (``heights``, :mod:`vision.pose.structure`)
    the prior is that height, held at 1 px per mm (:data:`W_TRIANGULATED`): one current view
    cannot tell a feature's height from the object's shift when the camera moved along the
    belt relative to it, the taught views can.  Elsewhere it is the top face, pulled weakly
    (0.1 px per 50 mm, :data:`W_UNKNOWN`) so that heights the views cannot tell apart stay
    where the plane fit put them instead of wandering.  A correspondence listed twice (a
    keypoint with two orientations) counts once, and those the first fit leaves more than
    :data:`REJECT_PX` off are dropped before a second fit.  The problem is a small bundle
    adjustment (Triggs et al. [1]_) solved with a sparse Jacobian (``scipy.optimize.
    least_squares``, trust-region reflective with bounds).

    Parameters
    ----------
    inlier_xy : ndarray of shape (N, 4)
        Correspondences: trained ``x, y``, current ``x, y``, pixels.
    camera : PinholeCamera
    T_base_cam_view, T_base_cam_now : ndarray of shape (4, 4)
        Camera poses of the trained view and of the current exposure.
    T_delta0 : ndarray of shape (4, 4)
        The start: the plane fit's motion.
    z_floor_m, z_top_m : float
        Heights of the belt surface and of the top face, metres.
    heights : ndarray of shape (N,), optional
        Triangulated heights of the trained features (``nan`` where unknown).

    Returns
    -------
    (T_delta, reproj_px) or None
        The motion and the RMS reprojection error of the correspondences kept, pixels;
        ``None`` when the solver fails, or when it moved the start by more than
        :data:`MAX_REFINE_SHIFT_M` / :data:`MAX_REFINE_YAW_RAD`.

    References
    ----------
    .. [1] B. Triggs, P. McLauchlan, R. Hartley and A. Fitzgibbon, "Bundle adjustment - a
       modern synthesis", LNCS 1883, Springer, 2000, 298-372.
    """
    refined = fit_motion(
        [(np.asarray(inlier_xy, dtype=np.float64).reshape(-1, 4), T_base_cam_view, np.eye(4),
          heights, None)],
        camera=camera, T_base_cam_now=T_base_cam_now, T_delta0=T_delta0, z_floor_m=z_floor_m,
        z_top_m=z_top_m,
    )  # fmt: skip
    return None if refined is None else refined[:2]


#: One trained view's share of a joint fit: its correspondences (trained ``x, y``, current
#: ``x, y``), its camera pose, the planar map from its teach-time object frame to the
#: reference view's (``T_taught_ref @ inv(T_taught_view)``; identity for the reference),
#: the triangulated heights of its trained features (``nan`` where unknown) or None, and
#: how firmly each is held, pixels per metre (None: :data:`W_TRIANGULATED` for all).
Group = tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64],
               NDArray[np.float64] | None, NDArray[np.float64] | None]  # fmt: skip

#: Weight of a triangulated height's prior, pixels per metre: a millimetre off it costs as
#: much as a pixel of reprojection error (the triangulation's own error is about that).
W_TRIANGULATED = 1000.0
#: Weight of the pull of a height the views did not triangulate towards the top face.
W_UNKNOWN = 2.0


def fit_motion(
    groups: list[Group],
    *,
    camera: PinholeCamera,
    T_base_cam_now: NDArray[np.float64],
    T_delta0: NDArray[np.float64],
    z_floor_m: float,
    z_top_m: float,
) -> tuple[NDArray[np.float64], float, int, int] | None:
    """:func:`refine_with_parallax` over the correspondences of one or several trained
    views at once: one motion of the reference view's object frame, each feature on its
    own view's trained ray, moved into the reference frame by its group's map first.
    Returns ``(T_delta, RMS reprojection error in px, correspondences used, of them held
    at a triangulated height)``: at most :data:`MAX_PARALLAX_POINTS` shared out between
    the views."""
    from scipy.optimize import OptimizeResult, least_squares
    from scipy.sparse import lil_matrix

    per_view = max(MIN_PARALLAX_POINTS, MAX_PARALLAX_POINTS // max(1, len(groups)))
    P0, D = [], []
    obs_all, z_prior, w_prior, held = [], [], [], []
    for pairs, T_view, T_align, known, firm in groups:
        zk = np.full(len(pairs), np.nan) if known is None else np.asarray(known, np.float64)
        if len(zk) != len(pairs):
            zk = np.full(len(pairs), np.nan)
        wk = np.full(len(pairs), W_TRIANGULATED) if firm is None else np.asarray(firm, np.float64)
        if len(wk) != len(pairs):
            wk = np.full(len(pairs), W_TRIANGULATED)
        # A keypoint with two dominant orientations is two keypoints at one place, and two
        # such matched to two give the same correspondence twice: counted once.
        _, first = np.unique(np.round(pairs, 2), axis=0, return_index=True)
        first = np.sort(first)
        pairs, zk, wk = pairs[first][:per_view], zk[first][:per_view], wk[first][:per_view]
        tri = np.isfinite(zk) & np.isfinite(wk) & (wk > 0)
        z_prior.append(np.where(tri, zk, z_top_m))
        w_prior.append(np.where(tri, np.minimum(wk, W_TRIANGULATED), W_UNKNOWN))
        held.append(tri)
        Tv = np.asarray(T_view, dtype=np.float64)
        d = viewing_rays(pairs[:, :2], camera, Tv)
        if np.any(d[:, 2] > -1e-6):
            return None  # a trained ray that does not go down to the belt
        A = np.asarray(T_align, dtype=np.float64)
        # The ray in the reference frame: origin and direction through the group's map
        # (a turn about z and a shift, so heights are kept).
        P0.append(np.broadcast_to(A[:3, :3] @ Tv[:3, 3] + A[:3, 3], d.shape))
        D.append(d @ A[:3, :3].T)
        obs_all.append(
            cv2.undistortPoints(
                pairs[:, 2:].reshape(-1, 1, 2), camera.K, np.asarray(camera.dist, np.float64)
            ).reshape(-1, 2)
        )
    C0, d, obs = np.concatenate(P0), np.concatenate(D), np.concatenate(obs_all)
    zp, wp, tri_all = np.concatenate(z_prior), np.concatenate(w_prior), np.concatenate(held)
    n = len(d)
    Tn = np.asarray(T_base_cam_now, dtype=np.float64)
    f = float(camera.K[0, 0])
    Rn_T, Cn = Tn[:3, :3].T, Tn[:3, 3]
    lo, hi = z_floor_m - 0.001, z_top_m + 0.001
    zp = np.clip(zp, lo, hi)

    def residuals(x: NDArray[np.float64], k: NDArray[np.intp]) -> NDArray[np.float64]:
        yaw, tx, ty, z = x[0], x[1], x[2], x[3:]
        s = (z - C0[k, 2]) / d[k, 2]
        P = C0[k] + s[:, None] * d[k]
        c, si = math.cos(yaw), math.sin(yaw)
        Q = np.stack([c * P[:, 0] - si * P[:, 1] + tx, si * P[:, 0] + c * P[:, 1] + ty, P[:, 2]], 1)
        pc = (Q - Cn) @ Rn_T.T
        pc_z = np.where(np.abs(pc[:, 2]) < 1e-9, 1e-9, pc[:, 2])
        uv = pc[:, :2] / pc_z[:, None]
        return np.concatenate([f * (uv - obs[k]).ravel(), wp[k] * (z - zp[k])])

    def solve(k: NDArray[np.intp], x0: NDArray[np.float64]) -> OptimizeResult | None:
        m = len(k)
        sparsity = lil_matrix((3 * m, 3 + m), dtype=int)
        rows = np.arange(m)
        sparsity[: 2 * m, :3] = 1
        sparsity[2 * rows, 3 + rows] = 1
        sparsity[2 * rows + 1, 3 + rows] = 1
        sparsity[2 * m + rows, 3 + rows] = 1
        lb = np.concatenate([[-np.inf] * 3, np.full(m, lo)])
        ub = np.concatenate([[np.inf] * 3, np.full(m, hi)])
        try:
            sol = least_squares(
                residuals, x0, bounds=(lb, ub), jac_sparsity=sparsity, loss="soft_l1",
                f_scale=PARALLAX_F_SCALE_PX, x_scale="jac", max_nfev=1000, args=(k,),
            )  # fmt: skip
        except (ValueError, np.linalg.LinAlgError):
            return None
        if not sol.success or not np.all(np.isfinite(sol.x)):
            return None
        return sol

    yaw0 = math.atan2(T_delta0[1, 0], T_delta0[0, 0])
    x0 = np.concatenate([[yaw0, T_delta0[0, 3], T_delta0[1, 3]], zp])
    x0[3:] = np.clip(x0[3:], lo + 1e-9, hi - 1e-9)
    keep = np.arange(n)
    sol = solve(keep, x0)
    if sol is None:
        return None
    # The robust loss only lessens an outlier's pull.  Correspondences that do not move
    # rigidly with the part (shading on a round surface, which stays with the lights while
    # the part turns; a corner where an edge crosses another one at another height) and
    # that the fit leaves beyond the verification's threshold are dropped, and the rest is
    # fitted again from where the first fit ended.
    off_px = np.linalg.norm(sol.fun[: 2 * n].reshape(-1, 2), axis=1)
    ok = off_px <= REJECT_PX
    if not ok.all() and int(ok.sum()) >= MIN_PARALLAX_POINTS:
        keep = np.flatnonzero(ok)
        sol = solve(keep, np.concatenate([sol.x[:3], sol.x[3:][keep]]))
        if sol is None:
            return None
    n = len(keep)
    tri_all = tri_all[keep]
    yaw, tx, ty = (float(v) for v in sol.x[:3])
    T = np.eye(4)
    c, si = math.cos(yaw), math.sin(yaw)
    T[:2, :2] = [[c, -si], [si, c]]
    T[:2, 3] = (tx, ty)
    # The shift is that of the features' centre (T_delta turns about the base origin, so
    # its own translation moves by metres per radian).
    centre = np.append((C0 + ((z_top_m - C0[:, 2]) / d[:, 2])[:, None] * d).mean(axis=0)[:2], 1.0)
    shift = (T[:2, [0, 1, 3]] - T_delta0[:2, [0, 1, 3]]) @ centre
    if (
        float(np.linalg.norm(shift)) > MAX_REFINE_SHIFT_M
        or abs(math.remainder(yaw - yaw0, 2 * math.pi)) > MAX_REFINE_YAW_RAD
    ):
        return None
    reproj = float(np.sqrt(np.mean(sol.fun[: 2 * n].reshape(-1, 2) ** 2) * 2))
    return T, reproj, n, int(np.count_nonzero(tri_all))
