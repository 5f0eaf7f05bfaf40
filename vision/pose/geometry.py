"""Planar geometry of an object's pose on the belt: back-projection, rays, rigid fits.

The object lies on the belt, a horizontal plane of the base frame, so its pose is a planar
rigid motion (a turn about the belt normal and a shift) of a known frame.  The pieces here
are the geometry every pose estimate shares:

* :func:`plane_points` cuts the undistorted viewing rays of pixels (chapter eqs. 1-5,
  inverted) with a horizontal plane ``z = z_plane_m`` of the base frame;
* :func:`plane_motion` is the least-squares planar rigid motion between two point sets,
  the Kabsch/Umeyama solution without scale;
* :func:`viewing_rays`, :func:`object_rays` and :func:`closest_points` give the rays of
  pixels and the common perpendicular of two lines, the midpoint triangulation of
  Hartley and Zisserman;
* :class:`ObjectPose` is the result every estimate returns.

References
----------
.. [1] W. Kabsch, "A solution for the best rotation to relate two sets of vectors",
   Acta Crystallographica A32 (1976), 922-923.
.. [2] S. Umeyama, "Least-squares estimation of transformation parameters between two
   point patterns", IEEE Trans. PAMI 13(4) (1991), 376-380.
.. [3] R. Hartley and A. Zisserman, *Multiple View Geometry in Computer Vision*, 2nd ed.,
   Cambridge University Press, 2003, section 12.2 (midpoint of the common perpendicular).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from vision.camera import PinholeCamera
from vision.errors import VisionCellError

__all__ = [
    "ObjectPose",
    "PoseFailed",
    "closest_points",
    "object_rays",
    "plane_motion",
    "plane_points",
    "pose_apart",
    "predict_along_belt",
    "rests_on_too_little",
    "rigid_motion_2d",
    "sample_region",
    "viewing_rays",
    "yaw_of",
]


class PoseFailed(VisionCellError):
    """The pose could not be computed from the top view."""

    code = "pose_failed"


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


def yaw_of(T: NDArray[np.float64]) -> float:
    """Rotation of a pose about the belt normal (base z), radians.

    Parameters
    ----------
    T : ndarray of shape (4, 4)
        A pose whose rotation is a turn about z (a level frame).

    Returns
    -------
    float
        ``atan2(T[1, 0], T[0, 0])``, in (-pi, pi].
    """
    return math.atan2(T[1, 0], T[0, 0])


def plane_points(
    px: NDArray[np.float64],
    camera: PinholeCamera,
    T_base_cam: NDArray[np.float64],
    z_plane_m: float,
) -> NDArray[np.float64]:
    """Back-project pixels onto the horizontal plane ``z = z_plane_m`` of the base frame.

    The pixels are undistorted with ``camera``'s ``K`` and ``dist`` (the inverse of the
    chapter's eqs. 2-5), the normalised rays ``(x, y, 1)`` turned into the base frame with
    ``T_base_cam`` and cut with the plane: ``P = t + s R (x, y, 1)`` with
    ``s = (z_plane_m - t_z) / (R (x, y, 1))_z``.

    Parameters
    ----------
    px : ndarray of shape (N, 2)
        Pixels ``(x, y)`` of the (distorted) image.
    camera : PinholeCamera
        Intrinsics ``K`` and distortion ``dist``.
    T_base_cam : ndarray of shape (4, 4)
        Camera pose (OpenCV frame) in the base frame.
    z_plane_m : float
        Height of the plane in the base frame, metres.

    Returns
    -------
    ndarray of shape (N, 3)
        The points on the plane, base frame, metres.

    Raises
    ------
    PoseFailed
        A ray parallel to the plane, or the plane behind the camera for some pixel.

    Examples
    --------
    A camera 1 m above the origin looking straight down sees its principal point at the
    origin:

    >>> import numpy as np
    >>> from vision.camera import PinholeCamera
    >>> cam = PinholeCamera(np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]]))
    >>> T = np.diag([1.0, -1.0, -1.0, 1.0]); T[2, 3] = 1.0
    >>> plane_points(np.array([[320.0, 240.0]]), cam, T, 0.0).round(6).tolist()
    [[0.0, 0.0, 0.0]]
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


def sample_region(
    mask: NDArray[np.bool_] | None, shape: tuple[int, int], n: int = 12
) -> NDArray[np.float64]:
    """Pixels of an ``n`` x ``n`` grid over the bounding box of ``mask`` that lie inside it.

    Parameters
    ----------
    mask : ndarray of shape (H, W), bool, or None
        The region; None or empty: the whole image.
    shape : (int, int)
        Image height and width (used when there is no region).
    n : int
        Grid points per side.

    Returns
    -------
    ndarray of shape (M, 2)
        Pixels ``(x, y)``, ``M <= n * n``.
    """
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


def rigid_motion_2d(
    a: NDArray[np.float64], b: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """Least-squares rigid motion of the plane mapping points ``a`` onto points ``b``.

    Minimises ``sum |R a_i + t - b_i|^2`` over rotations ``R`` (no reflection, no scale)
    and translations ``t``: with the centroids removed, ``R = U diag(1, det(U V^T)) V^T``
    from the SVD ``U S V^T`` of the cross-covariance ``sum (b_i - b) (a_i - a)^T``
    (Kabsch [1]_; Umeyama [2]_ eq. 39-40 with ``c = 1``), and ``t = b - R a``.

    Parameters
    ----------
    a, b : ndarray of shape (N, 2)
        Corresponding points, ``N >= 2``.

    Returns
    -------
    R : ndarray of shape (2, 2)
    t : ndarray of shape (2,)
    residual : float
        RMS distance ``|R a_i + t - b_i|`` (units of the points).

    Raises
    ------
    ValueError
        Shapes that differ or are not (N, 2) with N >= 2 (points that are not finite give
        a result that is not finite).

    References
    ----------
    .. [1] W. Kabsch, Acta Crystallographica A32 (1976), 922-923.
    .. [2] S. Umeyama, IEEE Trans. PAMI 13(4) (1991), 376-380.

    Examples
    --------
    >>> import numpy as np
    >>> a = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 2.0]])
    >>> R, t, r = rigid_motion_2d(a, a @ np.array([[0.0, 1.0], [-1.0, 0.0]]) + [3.0, 4.0])
    >>> R.round(12).tolist(), t.round(12).tolist(), round(r, 12)
    ([[0.0, -1.0], [1.0, 0.0]], [3.0, 4.0], 0.0)
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    if a.ndim != 2 or a.shape[1:] != (2,) or a.shape != b.shape or len(a) < 2:
        raise ValueError(
            f"a and b must both have shape (N, 2) with N >= 2, got {a.shape} and {b.shape}"
        )
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    M = (b - cb).T @ (a - ca)
    U, _, Vt = np.linalg.svd(M)
    D = np.diag([1.0, np.sign(np.linalg.det(U @ Vt))])
    R2 = U @ D @ Vt
    t2 = cb - R2 @ ca
    resid = float(np.sqrt(np.mean(np.sum((a @ R2.T + t2 - b) ** 2, axis=1))))
    return R2, t2, resid


def plane_motion(
    src_px: NDArray[np.float64],
    dst_px: NDArray[np.float64],
    camera: PinholeCamera,
    T_view: NDArray[np.float64],
    T_now: NDArray[np.float64],
    z: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """Planar rigid motion between pixels of one view and their images in another, both
    back-projected onto the plane ``z`` (:func:`plane_points`, :func:`rigid_motion_2d`).

    Parameters
    ----------
    src_px, dst_px : ndarray of shape (N, 2)
        Pixels of the trained view and where they are now.
    camera : PinholeCamera
    T_view, T_now : ndarray of shape (4, 4)
        Camera poses of the two views, base frame.
    z : float
        Height of the plane, metres.

    Returns
    -------
    R : ndarray of shape (2, 2)
    t : ndarray of shape (2,)
        Metres.
    residual : float
        RMS distance on the plane, metres.
    """
    a = plane_points(src_px, camera, T_view, z)[:, :2]
    b = plane_points(dst_px, camera, T_now, z)[:, :2]
    return rigid_motion_2d(a, b)


def viewing_rays(
    px: NDArray[np.float64], camera: PinholeCamera, T_base_cam: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Undistorted viewing rays of pixels, turned by the rotation of ``T_base_cam``.

    Parameters
    ----------
    px : ndarray of shape (N, 2)
    camera : PinholeCamera
    T_base_cam : ndarray of shape (4, 4)
        Pose of the camera in the frame the rays are wanted in.

    Returns
    -------
    ndarray of shape (N, 3)
        ``R (x, y, 1)`` for the normalised undistorted coordinates ``(x, y)`` (chapter
        eq. 1 inverted); not unit length.
    """
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
    """Camera centre, unit viewing rays and camera rotation in an object's frame.

    Parameters
    ----------
    px : ndarray of shape (N, 2)
    camera : PinholeCamera
    T_base_cam, T_base_obj : ndarray of shape (4, 4)
        Camera and object poses of the shot, base frame.

    Returns
    -------
    centre : ndarray of shape (3,)
    rays : ndarray of shape (N, 3)
        Unit directions.
    R_obj_cam : ndarray of shape (3, 3)
    """
    T = np.linalg.inv(np.asarray(T_base_obj, np.float64)) @ np.asarray(T_base_cam, np.float64)
    d = viewing_rays(px, camera, T)
    return T[:3, 3].copy(), d / np.linalg.norm(d, axis=1, keepdims=True), T[:3, :3]


def closest_points(
    o1: NDArray[np.float64], d1: NDArray[np.float64], o2: NDArray[np.float64],
    d2: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64],
           NDArray[np.float64]]:  # fmt: skip
    """Closest points of pairs of lines ``o1 + s d1`` and ``o2 + t d2`` (the feet of their
    common perpendicular; Hartley and Zisserman, section 12.2, midpoint method).

    With ``w = o1 - o2``, ``c = d1 . d2``, ``p = d1 . w``, ``q = d2 . w`` and unit
    directions, ``s = (c q - p) / (1 - c^2)`` and ``t = (q - c p) / (1 - c^2)``.

    Parameters
    ----------
    o1, d1, o2, d2 : ndarray of shape (..., 3)
        Origins and unit directions of the two lines of each pair.

    Returns
    -------
    P1, P2 : ndarray of shape (..., 3)
        The closest points on the first and the second line.
    s, t : ndarray of shape (...)
        Their parameters along the lines.
    sin2 : ndarray of shape (...)
        Squared sine of the angle between the lines; for parallel lines (``sin2`` below
        1e-12) ``s = t = 0`` rather than a division by zero.

    Examples
    --------
    >>> import numpy as np
    >>> P1, P2, s, t, sin2 = closest_points(
    ...     np.array([0.0, 0, 0]), np.array([1.0, 0, 0]),
    ...     np.array([0.0, 0, 1]), np.array([0.0, 1, 0]))
    >>> P1.tolist(), P2.tolist(), float(sin2)
    ([0.0, 0.0, 0.0], [0.0, 0.0, 1.0], 1.0)
    """
    w0 = o1 - o2
    cos = np.sum(d1 * d2, axis=-1)
    p, q = np.sum(d1 * w0, axis=-1), np.sum(d2 * w0, axis=-1)
    sin2 = np.clip(1.0 - cos * cos, 0.0, 1.0)
    den = np.where(sin2 > 1e-12, sin2, np.inf)
    s, t = (cos * q - p) / den, (q - cos * p) / den
    return o1 + s[..., None] * d1, o2 + t[..., None] * d2, s, t, sin2


def pose_apart(a: ObjectPose, b: ObjectPose) -> tuple[float, float]:
    """Distance on the belt plane and yaw difference of two poses.

    Returns
    -------
    distance_m : float
        Distance of the origins in base x, y, metres.
    dyaw_rad : float
        Yaw difference wrapped to [0, pi], radians.
    """
    d = float(np.linalg.norm(a.T_base_obj[:2, 3] - b.T_base_obj[:2, 3]))
    return d, abs(math.remainder(a.yaw_rad - b.yaw_rad, 2 * math.pi))


def rests_on_too_little(pose: ObjectPose | None) -> bool:
    """Whether a pose is too weakly supported to pick by.

    It is when there is none, when it is the plane answer alone (one trained view with too
    few correspondences for the parallax refinement, or a joint fit that failed) or when it
    was fitted to one trained view's correspondences alone: the plane answer ignores the
    features' heights, and a single view cannot tell a height from a shift along the
    camera's motion.  The inspection then takes a second top view.
    """
    return pose is None or pose.method == "plane" or pose.views < 2


def predict_along_belt(
    pose: ObjectPose, travel_m: float, direction: NDArray[np.float64] | None = None
) -> ObjectPose:
    """The pose moved ``travel_m`` along the belt (chapter 4.1, constant-speed mode).

    Parameters
    ----------
    pose : ObjectPose
        The pose at exposure.
    travel_m : float
        Belt travel since then, metres, within 5 m.
    direction : ndarray of shape (3,), optional
        Direction of travel, base frame (normalised here); default ``+y``.

    Raises
    ------
    PoseFailed
        A travel that is not finite or beyond 5 m.
    """
    if not math.isfinite(travel_m) or abs(travel_m) > 5.0:
        raise PoseFailed(f"belt travel must be finite and within 5 m, got {travel_m!r}")
    d = np.array([0.0, 1.0, 0.0]) if direction is None else np.asarray(direction, dtype=float)
    T = pose.T_base_obj.copy()
    T[:3, 3] += travel_m * d / np.linalg.norm(d)
    return dataclasses.replace(pose, T_base_obj=T)
