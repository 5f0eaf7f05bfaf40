"""The object's pose in the robot frame from the top view (issue 14, part 4; chapter 3.5, 4.1).

Recognition maps the best trained top view onto the current one with a plane homography
``H`` (``x_now ~ H @ x_view``, chapter eq. 12's planar case).  The trained view was taken
from a known camera pose (its stored joints, through ``T_base_ee(q) @ T_ee_cam``) with the
object in the model's frame (where it sat when taught: the station point, turned by the
view's yaw), and the current view from the camera pose at exposure.  Points of the object's
top face seen in the trained view are

1. undistorted with the active intrinsics and back-projected onto the horizontal plane of
   the top face (belt surface plus the model's height) from the trained camera,
2. mapped by ``H`` into the current image, undistorted and back-projected onto the same
   plane from the current camera,

and the planar rigid motion between the two point sets (least squares, Kabsch/Umeyama
without scale) is the object's motion since it was taught: ``T_base_obj = T_delta @
T_base_obj_taught``, its yaw the rotation about the belt normal.  The residual of the fit
(RMS, metres) says how well the points agree.

That plane is only right for a flat top.  The camera of the top view sits about 50 mm off
the station's vertical (the 5-DOF wrist, the camera beside the flange) and moves on a
circle with the camera roll, and the object turns under it, so the trained and the current
camera see the object from places up to 100 mm apart: features below the top face (a
wheel's spokes and hub, a bracket's base plate) shift by parallax, ``H`` averages them into
one plane's map, and back-projecting at the top face's height put the pose 3-5 mm off
(measured, ``benchmarks.inspection`` seeds 7, 1, 2: the error followed the plane height by
1-5 mm per 2 cm).  With the verification's inlier correspondences
(:attr:`vision.recognition.recognise.Candidate.inlier_xy`) the motion is therefore refined
by :func:`refine_with_parallax`: the planar motion and every feature's own height (on its
trained viewing ray, bounded between the belt and the top face) minimising the
reprojection error in the current image, started from the plane's answer.

One view cannot tell a feature's height from the object's shift when the two cameras
moved parallel to the belt (the parallax is then a shift too), so a part whose features
lie far below its height (the valve block's top face, 62 mm under its solenoid's cap) kept
a pose 4-17 mm off.  :func:`estimate_pose_views` therefore takes the model's other trained
top views that verify on the current one as well (taught at other object yaws and camera
rolls, they see the parallax in other directions), keeps the views whose answers agree
(a view registered on the wrong features, the pipe flange's bolt circle a sixth of a turn
off, is outvoted) and fits their correspondences together: one motion, every feature at
its own height on its own view's ray.  Where the views that agree on a wrong turn hold
the most correspondences (each of the flange's bolts looks like the next), the answers
are also judged by the outline: the trained region nearest in viewpoint, moved by each
answer, against the current region (:func:`silhouette_overlap`).

The heights need not be guessed per inspection: they are the model's.  The taught top
views were taken from known camera poses with the object in known frames, so features seen
in several of them are triangulated once (:mod:`backend.inspection.structure`) and the fit
holds each such feature near its triangulated height (:data:`W_TRIANGULATED`).  The pipe
flange's shiny steel and round outlines leave few features that two taught views match to
each other (4 % of them), but most current keypoints are matched by two to five of the
agreeing views: where their trained rays meet in the model's frame is the feature's place,
and the fit holds it there as firmly as the rays' angle fixes it (:func:`_rays_met`).  Only
the features placed neither way keep the weak pull towards the top face.

With the belt running (constant-speed mode, section 4.1) the pose is that at exposure;
:func:`predict_along_belt` moves it forward by the belt's travel since then.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from vision.camera import PinholeCamera
from vision.errors import VisionCellError
from vision.recognition.recognise import REPROJ_PX

__all__ = [
    "ObjectPose",
    "PoseFailed",
    "SilhouetteView",
    "ViewMatch",
    "closest_points",
    "estimate_pose",
    "estimate_pose_views",
    "object_rays",
    "plane_points",
    "pose_apart",
    "predict_along_belt",
    "refine_with_parallax",
    "rests_on_too_little",
    "silhouette_overlap",
    "viewing_rays",
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
#: Pixels beyond which a correspondence counts as an outlier in the robust loss: about
#: the median distance of the pipe flange's inliers from where the true motion puts them
#: (0.7 px; 1.5 px before: with the rejection below, its position p95 went from 1.07-1.19
#: to 0.73-0.80 mm on recorded fits, ``benchmarks.pose_replay``; README, eleventh part).
PARALLAX_F_SCALE_PX = 0.75
#: A correspondence the first fit leaves further than this from its prediction, pixels, is
#: dropped and the fit run again: the verification's own inlier threshold
#: (:data:`vision.recognition.recognise.REPROJ_PX`), now with every feature at its height.
REJECT_PX = REPROJ_PX


class PoseFailed(VisionCellError):
    """The pose could not be computed from the top view."""

    code = "pose_failed"
    http_status = 422


@dataclass(frozen=True, eq=False)
class ObjectPose:
    """The object's pose on the belt plane.

    Attributes
    ----------
    T_base_obj : ndarray of shape (4, 4)
        Object frame (footprint centre on the belt, z up) in the base frame.
    yaw_rad : float
        Rotation about the belt normal relative to the base frame's x axis, radians.
    residual_m : float
        RMS distance between the mapped and the back-projected points on the plane.
    n_points : int
        Points used in the fit.
    method : {"plane", "parallax"}
        The top-face plane fit alone, or refined with the features' heights.
    reproj_px : float or None
        With ``"parallax"``: RMS reprojection error of the correspondences, pixels.
    """

    T_base_obj: NDArray[np.float64]
    yaw_rad: float
    residual_m: float
    n_points: int
    method: str = "plane"
    reproj_px: float | None = None
    views: int = 1
    """Trained top views whose correspondences the pose was fitted to."""
    hypotheses: tuple[dict[str, object], ...] = ()
    """With several views: every group of agreeing views considered (its plane answer,
    views, correspondences, silhouette overlap) and which one the pose came from."""
    triangulated: int = 0
    """Correspondences of the fit held at a height triangulated from the taught views (the
    model's own, or where two of the agreeing views' rays to one current keypoint meet)."""

    def public(self) -> dict[str, object]:
        """JSON-friendly form (metres and radians)."""
        return {
            "T_base_obj": self.T_base_obj.tolist(),
            "position_m": [float(v) for v in self.T_base_obj[:3, 3]],
            "yaw_rad": self.yaw_rad,
            "residual_m": self.residual_m,
            "n_points": self.n_points,
            "method": self.method,
            "reproj_px": self.reproj_px,
            "views": self.views,
            "hypotheses": list(self.hypotheses),
            "triangulated": self.triangulated,
        }


def _yaw_of(T: NDArray[np.float64]) -> float:
    """Rotation of a pose about the belt normal (base z), radians."""
    return math.atan2(T[1, 0], T[0, 0])


def plane_points(
    px: NDArray[np.float64],
    camera: PinholeCamera,
    T_base_cam: NDArray[np.float64],
    z_plane_m: float,
) -> NDArray[np.float64]:
    """Back-project pixels (N, 2) onto the plane ``z = z_plane_m`` of the base frame.

    The pixels are undistorted with ``camera``'s ``K`` and ``dist`` (eq. 2-4), the rays
    turned into the base frame with ``T_base_cam`` and cut with the plane.  Returns (N, 3).
    """
    pts = np.asarray(px, dtype=np.float64).reshape(-1, 1, 2)
    norm = cv2.undistortPoints(pts, camera.K, np.asarray(camera.dist, dtype=np.float64))
    rays = np.concatenate([norm.reshape(-1, 2), np.ones((len(pts), 1))], axis=1)
    R, t = T_base_cam[:3, :3], T_base_cam[:3, 3]
    d = rays @ R.T
    if np.any(np.abs(d[:, 2]) < 1e-6):
        raise PoseFailed("a viewing ray is parallel to the belt plane")
    s = (z_plane_m - t[2]) / d[:, 2]
    if np.any(s <= 0):
        raise PoseFailed("the belt plane lies behind the camera for some pixels")
    return t + s[:, None] * d


def _sample_region(
    mask: NDArray[np.bool_] | None, shape: tuple[int, int], n: int = 12
) -> NDArray[np.float64]:
    """An n x n grid of pixels inside ``mask`` (or the whole image), as (N, 2) x, y."""
    h, w = shape
    if mask is not None and mask.any():
        ys, xs = np.nonzero(mask)
        x0, x1, y0, y1 = xs.min(), xs.max(), ys.min(), ys.max()
    else:
        x0, x1, y0, y1 = 0, w - 1, 0, h - 1
    gx, gy = np.meshgrid(np.linspace(x0, x1, n), np.linspace(y0, y1, n))
    pts = np.stack([gx.ravel(), gy.ravel()], axis=1)
    if mask is not None and mask.any():
        inside = mask[pts[:, 1].round().astype(int), pts[:, 0].round().astype(int)]
        pts = pts[inside]
    return pts


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
        views (:mod:`backend.inspection.structure`; ``nan`` where unknown): the refinement
        holds those features near them.

    Raises
    ------
    PoseFailed
        Degenerate homography, too few points, or a residual above :data:`MAX_RESIDUAL_M`.
    """
    Hm = np.asarray(H, dtype=np.float64)
    if Hm.shape != (3, 3) or not np.all(np.isfinite(Hm)) or abs(np.linalg.det(Hm)) < 1e-12:
        raise PoseFailed("the recognition gave no usable homography for the top view")
    src = _sample_region(view_mask, view_shape)
    if len(src) < 4:
        raise PoseFailed(f"only {len(src)} points inside the trained view's mask")
    dst = cv2.perspectiveTransform(src.reshape(-1, 1, 2), Hm).reshape(-1, 2)
    src_px: np.ndarray = np.asarray(src, dtype=np.float64)
    dst_px: np.ndarray = np.asarray(dst, dtype=np.float64)
    R2, t2, resid = _plane_fit(src_px, dst_px, camera, T_base_cam_view, T_base_cam_now, z_plane_m)
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
            refined = _refine(
                [(pairs, T_base_cam_view, np.eye(4), heights, None)], camera=camera,
                T_base_cam_now=T_base_cam_now, T_delta0=T_delta, z_floor_m=z_floor_m,
                z_top_m=z_plane_m,
            )  # fmt: skip
            if refined is not None:
                T_delta, reproj, n, n_tri = refined
                method = "parallax"
    T = T_delta @ np.asarray(T_base_obj_taught, dtype=np.float64)
    return ObjectPose(T, _yaw_of(T), resid, n, method, reproj, triangulated=n_tri)


def _plane_fit(
    src_px: NDArray[np.float64],
    dst_px: NDArray[np.float64],
    camera: PinholeCamera,
    T_view: NDArray[np.float64],
    T_now: NDArray[np.float64],
    z: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """Planar rigid motion (Kabsch without scale) between the trained pixels and their
    mapped pixels back-projected on the plane ``z``: ``(R 2x2, t 2, RMS residual m)``."""
    a = plane_points(src_px, camera, T_view, z)[:, :2]
    b = plane_points(dst_px, camera, T_now, z)[:, :2]
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    M = (b - cb).T @ (a - ca)
    U, _, Vt = np.linalg.svd(M)
    D = np.diag([1.0, np.sign(np.linalg.det(U @ Vt))])
    R2 = U @ D @ Vt
    t2 = cb - R2 @ ca
    resid = float(np.sqrt(np.mean(np.sum((a @ R2.T + t2 - b) ** 2, axis=1))))
    return R2, t2, resid


def viewing_rays(
    px: NDArray[np.float64], camera: PinholeCamera, T_base_cam: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Undistorted viewing rays (N, 3) of pixels in the frame ``T_base_cam`` maps the camera
    into (the base frame here; not normalised)."""
    pts = np.asarray(px, dtype=np.float64).reshape(-1, 1, 2)
    norm = cv2.undistortPoints(pts, camera.K, np.asarray(camera.dist, dtype=np.float64))
    rays = np.concatenate([norm.reshape(-1, 2), np.ones((len(pts), 1))], axis=1)
    return rays @ np.asarray(T_base_cam, dtype=np.float64)[:3, :3].T


def object_rays(
    px: NDArray[np.float64],
    camera: PinholeCamera,
    T_base_cam: NDArray[np.float64],
    T_base_obj: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The camera centre (3,), the unit viewing rays (N, 3) of pixels ``px`` and the camera
    rotation (3, 3), all in the object frame ``T_base_obj`` of the shot."""
    T = np.linalg.inv(np.asarray(T_base_obj, np.float64)) @ np.asarray(T_base_cam, np.float64)
    d = viewing_rays(px, camera, T)
    return T[:3, 3].copy(), d / np.linalg.norm(d, axis=1, keepdims=True), T[:3, :3]


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
    taught views triangulated the feature (``heights``, :mod:`backend.inspection.structure`)
    the prior is that height, held at 1 px per mm (:data:`W_TRIANGULATED`): one current view
    cannot tell a feature's height from the object's shift when the camera moved along the
    belt relative to it, the taught views can.  Elsewhere it is the top face, pulled weakly
    (0.1 px per 50 mm, :data:`W_UNKNOWN`) so that heights the views cannot tell apart stay
    where the plane fit put them instead of wandering.  A correspondence listed twice (a
    keypoint with two orientations) counts once, and those the first fit leaves more than
    :data:`REJECT_PX` off are dropped before a second fit.  Returns ``(T_delta, RMS
    reprojection error in px)`` of the correspondences kept; ``None``
    when the solver fails, or when it moved the start by more than
    :data:`MAX_REFINE_SHIFT_M` / :data:`MAX_REFINE_YAW_RAD`.
    """
    refined = _refine(
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
_Group = tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64],
               NDArray[np.float64] | None, NDArray[np.float64] | None]  # fmt: skip

#: Weight of a triangulated height's prior, pixels per metre: a millimetre off it costs as
#: much as a pixel of reprojection error (the triangulation's own error is about that).
W_TRIANGULATED = 1000.0
#: Weight of the pull of a height the views did not triangulate towards the top face.
W_UNKNOWN = 2.0


def _refine(
    groups: list[_Group],
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
        unknown; :mod:`backend.inspection.structure`), or ``None``.
    """

    H: NDArray[np.float64]
    inlier_xy: NDArray[np.float64]
    T_base_cam_view: NDArray[np.float64]
    T_base_obj_taught: NDArray[np.float64]
    view_mask: NDArray[np.bool_] | None
    view_shape: tuple[int, int]
    heights: NDArray[np.float64] | None = None


@dataclass(frozen=True, eq=False)
class SilhouetteView:
    """A trained top view of the model whose region can be compared with the current one:
    its camera pose, the model frame as it saw it, and its region (``mask()``, decoded
    when first asked for: only the views nearest an answer's viewpoint are)."""

    T_base_cam_view: NDArray[np.float64]
    T_base_obj_taught: NDArray[np.float64]
    mask: Callable[[], NDArray[np.bool_] | None]


#: Two trained views' plane poses agree when within this distance and turn of each other
#: (the plane answer alone is 3-5 mm off for parts with features below the top face; a
#: view registered on the wrong features, the pipe flange's bolt circle a sixth of a turn
#: off or the valve block on a handful of look-alike corners, is tens of millimetres or
#: degrees away).
AGREE_M = 0.008
AGREE_YAW_RAD = math.radians(4.0)


#: Groups of agreeing views whose answers overlap the current region (intersection over
#: union of the trained silhouette moved by the answer) within this much of the best group
#: fit the outline equally well; a group needs at least :data:`SILHOUETTE_MIN_SHARE` of the
#: leading group's correspondences to be considered.
SILHOUETTE_TOLERANCE = 0.02
SILHOUETTE_MIN_SHARE = 0.2
#: Largest shift of the moved trained region searched, as a share of the current region's
#: size (the answers' positions are a few millimetres off; a turn moves more).
SILHOUETTE_SHIFT = 0.04


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
    differ there by far more.  Empty regions overlap 0; ``nan`` when the plane cannot be
    back-projected from the trained camera.
    """
    vm = np.asarray(view_mask, dtype=bool)
    qm = np.asarray(query_mask, dtype=bool)
    if not vm.any() or not qm.any():
        return 0.0
    src = _sample_region(vm, vm.shape, n=8)
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


def pose_apart(a: ObjectPose, b: ObjectPose) -> tuple[float, float]:
    """Distance on the belt plane (metres) and yaw difference (radians, in [0, pi]) of two
    poses."""
    d = float(np.linalg.norm(a.T_base_obj[:2, 3] - b.T_base_obj[:2, 3]))
    return d, abs(math.remainder(a.yaw_rad - b.yaw_rad, 2 * math.pi))


def rests_on_too_little(pose: ObjectPose | None) -> bool:
    """Whether a pose is too weakly supported to pick by: none, the plane answer (one
    trained view with fewer than :data:`MIN_PARALLAX_POINTS` correspondences, or a joint
    fit that failed) or a fit to one trained view's correspondences alone.

    Over 483 recorded fits (``benchmarks.pose_replay``, pipe flange seeds 6, 7, 8 and
    every part seed 11) the plane answers were exactly the five poses off by more than
    2 mm or 1 deg.  In the thirteenth part's runs (718 poses) three rested on one view
    (9, 12 and 16 correspondences): 0.2, 3.0 and 0.1 mm off.  The inspection then takes a
    second top view (:func:`backend.inspection.service._second_top_view`)."""
    return pose is None or pose.method == "plane" or pose.views < 2


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
    groups are also judged by their silhouettes (:func:`_by_silhouette`): the trained
    region of ``silhouettes`` (every taught top view of the model; default: the matches'
    own masks) nearest each answer's viewpoint, moved by that answer, against the current
    region.  A part whose features repeat round a circle (the pipe flange's bolts) can
    register a sixth of a turn off on as many correspondences as it registers right; its
    outline (the side nozzle) cannot.  Every group considered is recorded in
    :attr:`ObjectPose.hypotheses`.

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
    hyps, chosen = _by_silhouette(
        [groups_seen[i] for i in order], camera=camera, T_base_cam_now=T_base_cam_now,
        z_m=0.5 * (z_plane_m + z_floor_m), query_mask=query_mask,
        silhouettes=silhouettes if silhouettes is not None else [
            SilhouetteView(m.T_base_cam_view, m.T_base_obj_taught, _const(m.view_mask))
            for m in matches if m.view_mask is not None
        ],
    )  # fmt: skip
    best, best_n = chosen
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
    groups: list[_Group] = []
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
    refined = _refine(groups, camera=camera, T_base_cam_now=T_base_cam_now, T_delta0=T_delta0,
                      z_floor_m=z_floor_m, z_top_m=z_plane_m)  # fmt: skip
    if refined is None:
        return dataclasses.replace(single(), hypotheses=hyps)
    T_delta, reproj, n_used, n_tri = refined
    T = T_delta @ T_ref
    return ObjectPose(T, _yaw_of(T), lead.residual_m, n_used, "parallax", reproj, len(groups), hyps,
                      n_tri)  # fmt: skip


def closest_points(
    o1: NDArray[np.float64], d1: NDArray[np.float64], o2: NDArray[np.float64],
    d2: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64],
           NDArray[np.float64]]:  # fmt: skip
    """Closest points ``o1 + s d1`` and ``o2 + t d2`` of pairs of lines with unit directions
    (rows), with ``s``, ``t`` and the squared sine of the angle between the lines (parallel
    lines, sine below 1e-6: ``s = t = 0`` rather than a division by zero)."""
    w0 = o1 - o2
    cos = np.sum(d1 * d2, axis=-1)
    p, q = np.sum(d1 * w0, axis=-1), np.sum(d2 * w0, axis=-1)
    sin2 = np.clip(1.0 - cos * cos, 0.0, 1.0)
    den = np.where(sin2 > 1e-12, sin2, np.inf)
    s, t = (cos * q - p) / den, (q - cos * p) / den
    return o1 + s[..., None] * d1, o2 + t[..., None] * d2, s, t, sin2


#: Correspondences of two agreeing trained views share a current keypoint when their
#: current points lie within this distance, pixels (one detection gives one point).
SAME_KEYPOINT_PX = 0.5
#: Their trained rays meet at a point of the part when they pass within this distance of
#: each other in the model's frame, pixels at the point's depth (``benchmarks.pose_replay``
#: on the pipe flange: 1 and 2 px alike; README, twelfth part).
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
    for the features they matched to each other (:mod:`backend.inspection.structure`, which
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


def predict_along_belt(
    pose: ObjectPose, travel_m: float, direction: NDArray[np.float64] | None = None
) -> ObjectPose:
    """The pose moved ``travel_m`` along the belt (default direction +y of the base)."""
    if not math.isfinite(travel_m) or abs(travel_m) > 5.0:
        raise PoseFailed(f"belt travel must be finite and within 5 m, got {travel_m!r}")
    d = np.array([0.0, 1.0, 0.0]) if direction is None else np.asarray(direction, dtype=float)
    T = pose.T_base_obj.copy()
    T[:3, 3] += travel_m * d / np.linalg.norm(d)
    return dataclasses.replace(pose, T_base_obj=T)


def _const(mask: NDArray[np.bool_] | None) -> Callable[[], NDArray[np.bool_] | None]:
    return lambda: mask


_Hyp = tuple[list[tuple[ViewMatch, ObjectPose]], int]


def _by_silhouette(
    ranked: list[_Hyp],
    *,
    camera: PinholeCamera,
    T_base_cam_now: NDArray[np.float64],
    z_m: float,
    query_mask: NDArray[np.bool_] | None,
    silhouettes: list[SilhouetteView],
) -> tuple[tuple[dict[str, object], ...], _Hyp]:
    """Of the groups of agreeing views (``ranked``: most correspondences first), the one
    to fit: the first of those (with at least :data:`SILHOUETTE_MIN_SHARE` of the leading
    group's correspondences) whose silhouette overlap is within
    :data:`SILHOUETTE_TOLERANCE` of the best.

    The outline settles what the correspondences cannot: a part whose features repeat
    round a circle registers a sixth of a turn off on as many of them as it registers
    right (the flange: 0.70 against 0.98), and a plane answer thrown far off by
    parallax or look-alike features (the bracket's 26 mm: 0.66 against 0.97) does not fit
    either.  Answers a few millimetres apart fit it about equally (the shift search
    absorbs them), and there the correspondences' joint fit is the better judge.

    A group's answer (its first view's plane pose) puts the current camera somewhere
    relative to the object; the trained view taken from nearest that place (the object
    frame of its teach) sees the outline with the least parallax, and its region moved
    by the answer is compared with the current one (:func:`silhouette_overlap`).
    Returns a record of every group and the chosen one.
    """
    cam_now = np.asarray(T_base_cam_now, dtype=np.float64)[:, 3]
    rel_views = [
        (np.linalg.inv(np.asarray(v.T_base_obj_taught, dtype=np.float64))
         @ np.asarray(v.T_base_cam_view, dtype=np.float64)[:, 3])[:3]
        for v in silhouettes
    ]  # fmt: skip
    ious: list[float | None] = []
    for group, _n in ranked:
        if query_mask is None or not silhouettes or len(ranked) == 1:
            ious.append(None)
            continue
        T_obj = group[0][1].T_base_obj
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
    lead_n = ranked[0][1]
    eligible = [i for i in range(len(ranked)) if ious[i] is not None
                and (i == 0 or ranked[i][1] >= SILHOUETTE_MIN_SHARE * lead_n)]  # fmt: skip
    pick = 0
    if ious[0] is not None and eligible:
        best_iou = max(float(ious[i] or 0.0) for i in eligible)
        pick = next(i for i in eligible if float(ious[i] or 0.0) >= best_iou - SILHOUETTE_TOLERANCE)
    record: tuple[dict[str, object], ...] = tuple(
        {
            "position_m": [float(v) for v in g[0][1].T_base_obj[:3, 3]],
            "yaw_rad": float(g[0][1].yaw_rad),
            "views": len(g),
            "correspondences": int(n),
            "silhouette_iou": None if iou is None else round(float(iou), 4),
            "chosen": i == pick,
        }
        for i, ((g, n), iou) in enumerate(zip(ranked, ious, strict=True))
    )
    return record, ranked[pick]
