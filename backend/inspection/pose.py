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

With the belt running (constant-speed mode, section 4.1) the pose is that at exposure;
:func:`predict_along_belt` moves it forward by the belt's travel since then.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from vision.camera import PinholeCamera
from vision.errors import VisionCellError

__all__ = ["ObjectPose", "PoseFailed", "estimate_pose", "plane_points", "predict_along_belt"]

#: Largest residual of the planar fit accepted, metres.
MAX_RESIDUAL_M = 0.01


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
    """

    T_base_obj: NDArray[np.float64]
    yaw_rad: float
    residual_m: float
    n_points: int

    def public(self) -> dict[str, object]:
        """JSON-friendly form (metres and radians)."""
        return {
            "T_base_obj": self.T_base_obj.tolist(),
            "position_m": [float(v) for v in self.T_base_obj[:3, 3]],
            "yaw_rad": self.yaw_rad,
            "residual_m": self.residual_m,
            "n_points": self.n_points,
        }


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
    a = plane_points(src_px, camera, T_base_cam_view, z_plane_m)[:, :2]
    b = plane_points(dst_px, camera, T_base_cam_now, z_plane_m)[:, :2]
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    M = (b - cb).T @ (a - ca)
    U, _, Vt = np.linalg.svd(M)
    D = np.diag([1.0, np.sign(np.linalg.det(U @ Vt))])
    R2 = U @ D @ Vt
    t2 = cb - R2 @ ca
    resid = float(np.sqrt(np.mean(np.sum((a @ R2.T + t2 - b) ** 2, axis=1))))
    if resid > MAX_RESIDUAL_M:
        raise PoseFailed(
            f"the top view's points disagree by {resid * 1e3:.1f} mm RMS after the planar fit "
            f"(limit {MAX_RESIDUAL_M * 1e3:.0f} mm): the homography is not a rigid motion"
        )
    T_delta = np.eye(4)
    T_delta[:2, :2] = R2
    T_delta[:2, 3] = t2
    T = T_delta @ np.asarray(T_base_obj_taught, dtype=np.float64)
    yaw = math.atan2(T[1, 0], T[0, 0])
    return ObjectPose(T, yaw, resid, len(src))


def predict_along_belt(
    pose: ObjectPose, travel_m: float, direction: NDArray[np.float64] | None = None
) -> ObjectPose:
    """The pose moved ``travel_m`` along the belt (default direction +y of the base)."""
    if not math.isfinite(travel_m) or abs(travel_m) > 5.0:
        raise PoseFailed(f"belt travel must be finite and within 5 m, got {travel_m!r}")
    d = np.array([0.0, 1.0, 0.0]) if direction is None else np.asarray(direction, dtype=float)
    T = pose.T_base_obj.copy()
    T[:3, 3] += travel_m * d / np.linalg.norm(d)
    return ObjectPose(T, pose.yaw_rad, pose.residual_m, pose.n_points)
