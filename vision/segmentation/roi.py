"""Where the object can be in a side view: the region of interest of viewpoints 2 and 3.

The side views are taken from cameras about 30 deg off vertical that see the object and a
good deal of belt and cell around it.  Matched over the whole frame, the query's features
are mostly belt and background (hundreds of keypoints) against trained side views whose
features were extracted inside the object's segmented region only; the background then
adds chance matches to every model.  The top view, segmented, says where the object is, so
the side query is restricted to the image of the space the object can occupy:

1. the convex hull of the object's region in the top view (its silhouette) is
   back-projected through the top camera (active intrinsics and hand-eye,
   :func:`vision.pose.plane_points`) onto the belt plane ``z0`` and onto the
   plane ``z0 + h`` of a height bound ``h``.  Every point of the object lies on a viewing
   ray through its silhouette and between the two planes, so the object lies inside the
   truncated cone (the visual hull of one view) spanned by the two polygons; it is convex,
   the convex hull of its two caps, and never wider than the vertical prism "footprint on
   the belt x [0, h]";
2. the caps, grown by ``margin_m`` about their centroid (pose and calibration error), are
   moved into the side camera (``inv(T_base_cam_side)``) and projected with the ideal
   pinhole (normalised coordinates, eq. 1): the image of a convex solid is the convex hull
   of its vertices' images;
3. every pixel of the side image whose undistorted normalised coordinates (the inverse of
   eqs. 3-5, computed once per camera) lie inside that hull is in the region; the region is
   then dilated by ``margin_px`` for the keypoints' support.

Whatever cannot be done (an empty or degenerate silhouette, a plane behind the camera, a
region off the image or empty) falls back to the whole frame, and :attr:`SideRoi.reason`
says why, for the inspection's stored reason.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterable
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from vision.camera import PinholeCamera
from vision.pose.geometry import PoseFailed, plane_points

__all__ = ["MAX_PART_HEIGHT_M", "SideRoi", "height_bound", "side_query", "side_roi"]

#: Height bound of an object when not every trained model has a stored height: the tallest
#: part the station admits (its viewpoints aim for objects up to this), metres.
MAX_PART_HEIGHT_M = 0.25
#: Smallest and largest footprint accepted (area on the belt plane, m^2): below, the top
#: view's region is a speck (segmentation noise); above, it is not one object at the station.
_MIN_AREA_M2 = 1e-5
_MAX_AREA_M2 = 0.25
#: Most hull vertices kept per cap (the silhouette's convex hull is decimated evenly).
_MAX_VERTICES = 64


@dataclass(frozen=True, eq=False)
class SideRoi:
    """The region of a side view where the object can be.

    Attributes
    ----------
    mask : ndarray of shape (H, W), uint8 (0 / 1), or None
        The region; None when falling back to the whole frame.
    reason : str
        How the region was made, or why the whole frame is used.
    fraction : float
        Share of the image inside the region (1.0 for the whole frame).
    """

    mask: NDArray[np.uint8] | None
    reason: str
    fraction: float


def height_bound(heights: Iterable[float | None], *, default_m: float = MAX_PART_HEIGHT_M) -> float:
    """Height bound of the object at the station before it is named: the tallest stored
    height of the trained models when every one has a height, else ``default_m``.

    Parameters
    ----------
    heights : iterable of float or None
        The trained models' heights, metres (None: unknown).
    default_m : float
        The bound when a height is unknown or there is none, metres, in (0, 1].

    Returns
    -------
    float
        Metres.

    Raises
    ------
    ValueError
        A height that is not a finite number in (0, 1] m.
    """
    if isinstance(default_m, bool) or not (
        isinstance(default_m, int | float) and math.isfinite(default_m) and 0.0 < default_m <= 1.0
    ):
        raise ValueError(f"default_m must be in (0, 1] m, got {default_m!r}")
    known: list[float] = []
    for h in heights:
        if h is None:
            return float(default_m)
        if isinstance(h, bool) or not (isinstance(h, int | float) and math.isfinite(h)):
            raise ValueError(f"a model height must be a finite number of metres, got {h!r}")
        if not 0.0 < h <= 1.0:
            raise ValueError(f"a model height must be in (0, 1] m, got {h!r}")
        known.append(float(h))
    return max(known) if known else float(default_m)


@functools.lru_cache(maxsize=4)
def _normalised_grid(K: bytes, dist: bytes, width: int, height: int) -> NDArray[np.float64]:
    """Undistorted normalised coordinates of every pixel, (H*W, 2), of one camera."""
    cam = PinholeCamera(
        np.frombuffer(K, dtype=np.float64).reshape(3, 3),
        np.frombuffer(dist, dtype=np.float64),
        width=width,
        height=height,
    )
    vv, uu = np.mgrid[0:height, 0:width].astype(np.float64)
    xy = cam.undistort_pixels(np.stack([uu.ravel(), vv.ravel()], axis=1), to_pixels=False)
    xy.setflags(write=False)
    return xy


def _check_T(T: object, name: str) -> NDArray[np.float64]:
    a = np.asarray(T, dtype=np.float64)
    if a.shape != (4, 4) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be a finite 4x4 transform, got shape {a.shape}")
    R = a[:3, :3]
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or not np.allclose(a[3], [0, 0, 0, 1]):
        raise ValueError(
            f"{name} must be a rigid transform (orthonormal rotation, last row 0 0 0 1)"
        )
    return a


def _whole(reason: str) -> SideRoi:
    return SideRoi(None, f"whole frame: {reason}", 1.0)


def _grown(cap: NDArray[np.float64], margin_m: float) -> NDArray[np.float64]:
    """The polygon ``cap`` (N, 3) moved ``margin_m`` outwards from its centroid in xy."""
    c = cap[:, :2].mean(axis=0)
    d = cap[:, :2] - c
    r = np.linalg.norm(d, axis=1, keepdims=True)
    out = cap.copy()
    out[:, :2] = c + d * (r + margin_m) / np.maximum(r, 1e-9)
    return out


def side_roi(
    top_mask: NDArray[np.bool_] | NDArray[np.uint8],
    *,
    camera: PinholeCamera,
    T_base_cam_top: NDArray[np.float64],
    T_base_cam_side: NDArray[np.float64],
    surface_z_m: float,
    height_m: float,
    image_shape: tuple[int, int],
    margin_m: float = 0.01,
    margin_px: int = 6,
    moved_m: tuple[float, float, float] | NDArray[np.float64] | None = None,
) -> SideRoi:
    """The side view's region of interest from the top view's segmentation (module docstring):
    the image of the visual hull of one view (Laurentini [1]_), bounded by the belt and a
    height, through the chapter's camera model (eqs. 1-5).

    Parameters
    ----------
    top_mask : ndarray of shape (H, W), bool or uint8
        The object's region in the top view.
    camera : PinholeCamera
        Active intrinsics (or the nominal camera) of both views; its size must be the side
        image's.
    T_base_cam_top, T_base_cam_side : ndarray of shape (4, 4)
        Camera poses (OpenCV frame) of the top view and of the side view, base frame.
    surface_z_m : float
        Height of the belt surface in the base frame, metres.
    height_m : float
        Height bound of the object above the belt, metres, in (0, 1]
        (:func:`height_bound`).
    image_shape : (int, int)
        Height and width of the side image.
    margin_m : float
        Growth of the footprint for pose and calibration error, metres, in [0, 0.1]; the
        height bound grows by the same.
    margin_px : int
        Dilation of the region in the side image, pixels, in 0..100.
    moved_m : array of shape (3,), optional
        The object's motion between the two exposures, base frame, metres (the belt's
        travel at constant speed; each component within 5 m).

    Returns
    -------
    SideRoi
        ``mask=None`` (whole frame) with the reason when the region cannot be made.

    Raises
    ------
    ValueError
        Inputs of the wrong type, shape or range (bad data, not a bad view).

    References
    ----------
    .. [1] A. Laurentini, "The visual hull concept for silhouette-based image
       understanding", IEEE Trans. PAMI 16(2) (1994), 150-162.
    """
    tm = np.asarray(top_mask)
    if tm.ndim != 2 or tm.dtype not in (np.bool_, np.uint8):
        raise ValueError(f"top_mask must be a 2D bool or uint8 array, got {tm.dtype} {tm.shape}")
    Tt = _check_T(T_base_cam_top, "T_base_cam_top")
    Ts = _check_T(T_base_cam_side, "T_base_cam_side")
    for name, v, lo, hi in (("surface_z_m", surface_z_m, -5.0, 5.0), ("height_m", height_m, 0.0, 1.0),
                            ("margin_m", margin_m, 0.0, 0.1)):  # fmt: skip
        if isinstance(v, bool) or not (isinstance(v, int | float) and math.isfinite(v)):
            raise ValueError(f"{name} must be a finite number, got {v!r}")
        if not lo <= v <= hi or (name == "height_m" and v == 0.0):
            raise ValueError(
                f"{name} must be in {'(' if name == 'height_m' else '['}{lo:g}, {hi:g}], got {v!r}"
            )
    if isinstance(margin_px, bool) or not isinstance(margin_px, int) or not 0 <= margin_px <= 100:
        raise ValueError(f"margin_px must be an integer in 0..100, got {margin_px!r}")
    if (
        not isinstance(image_shape, tuple | list)
        or len(image_shape) != 2
        or not all(isinstance(s, int | np.integer) and 16 <= s <= 10_000 for s in image_shape)
    ):
        raise ValueError(
            f"image_shape must be (height, width) in 16..10000 pixels, got {image_shape!r}"
        )
    H, W = int(image_shape[0]), int(image_shape[1])
    shift = np.zeros(3) if moved_m is None else np.asarray(moved_m, dtype=np.float64)
    if shift.shape != (3,) or not np.all(np.isfinite(shift)) or np.abs(shift).max() > 5.0:
        raise ValueError(
            f"moved_m must be 3 finite metres within 5 m, got {np.asarray(moved_m).tolist()}"
        )
    if (camera.height, camera.width) != (H, W):
        return _whole(f"the camera model is {camera.width}x{camera.height}, the image {W}x{H}")

    # 1. the silhouette's convex hull, back-projected onto the belt and the top planes.
    pts = cv2.findNonZero(tm.astype(np.uint8))
    if pts is None:
        return _whole("the top view's region is empty")
    hull = cv2.convexHull(pts).reshape(-1, 2).astype(np.float64)
    if len(hull) > _MAX_VERTICES:
        hull = hull[np.linspace(0, len(hull) - 1, _MAX_VERTICES).round().astype(int)]
    if len(hull) < 3:
        return _whole("the top view's region is a line or a point")
    try:
        low = plane_points(hull, camera, Tt, surface_z_m)
        high = plane_points(hull, camera, Tt, surface_z_m + height_m + margin_m)
    except PoseFailed as exc:
        return _whole(f"the top view's rays miss the belt ({exc.detail})")
    area = 0.5 * abs(float(np.dot(low[:, 0], np.roll(low[:, 1], 1))
                           - np.dot(low[:, 1], np.roll(low[:, 0], 1))))  # fmt: skip
    if not np.all(np.isfinite(low)) or not _MIN_AREA_M2 <= area <= _MAX_AREA_M2:
        return _whole(f"footprint of {area * 1e4:.2f} cm^2 on the belt is not one object")

    # 2. the grown caps in the side camera, ideal pinhole.
    solid = np.concatenate([_grown(low, margin_m), _grown(high, margin_m)])
    solid[: len(low), 2] -= margin_m
    solid += shift
    P = (np.linalg.inv(Ts) @ np.concatenate([solid, np.ones((len(solid), 1))], axis=1).T).T[:, :3]
    if np.any(P[:, 2] <= 1e-3):
        return _whole("part of the object's space lies behind the side camera")
    xy = P[:, :2] / P[:, 2:3]
    poly = cv2.convexHull(xy.astype(np.float32)).reshape(-1, 2).astype(np.float64)

    # 3. pixels whose undistorted coordinates fall inside the (counter-clockwise) hull.
    grid = _normalised_grid(np.ascontiguousarray(camera.K, dtype=np.float64).tobytes(),
                            np.ascontiguousarray(camera.dist, dtype=np.float64).tobytes(), W, H)  # fmt: skip
    if (np.roll(poly[:, 0], -1) - poly[:, 0]) @ (np.roll(poly[:, 1], -1) + poly[:, 1]) > 0:
        poly = poly[::-1]  # sum (x2 - x1)(y2 + y1) = -2 * signed area: make the area positive
    lo, hi = poly.min(axis=0), poly.max(axis=0)
    cand = np.flatnonzero(
        (grid[:, 0] >= lo[0])
        & (grid[:, 0] <= hi[0])
        & (grid[:, 1] >= lo[1])
        & (grid[:, 1] <= hi[1])
    )  # the hull's bounding box first: the edge tests only there
    g = grid[cand]
    keep = np.ones(len(cand), dtype=bool)
    for a, b in zip(poly, np.roll(poly, -1, axis=0), strict=True):
        e = b - a
        keep &= e[0] * (g[:, 1] - a[1]) - e[1] * (g[:, 0] - a[0]) >= 0
    inside = np.zeros(len(grid), dtype=bool)
    inside[cand[keep]] = True
    roi = inside.reshape(H, W).astype(np.uint8)
    if not roi.any():
        return _whole("the object's space projects off the side image")
    if margin_px:
        k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * margin_px + 1, 2 * margin_px + 1))
        roi = np.asarray(cv2.dilate(roi, k), dtype=np.uint8)
    frac = float(roi.mean())
    return SideRoi(
        roi,
        f"object's space ({height_m * 1e3:.0f} mm high) in {100 * frac:.0f} % of the frame",
        frac,
    )


def side_query(
    side_rgb: NDArray[np.uint8], roi: SideRoi
) -> NDArray[np.uint8] | tuple[NDArray[np.uint8], NDArray[np.uint8]]:
    """What a side viewpoint's ``look`` answers to :func:`vision.recognition.recognise_views`.

    Parameters
    ----------
    side_rgb : ndarray of shape (H, W, 3), uint8
    roi : SideRoi
        Its region of interest (:func:`side_roi`).

    Returns
    -------
    ndarray or (ndarray, ndarray)
        The image with the region as its mask, or the image alone (whole frame) when
        ``roi`` fell back.

    Raises
    ------
    ValueError
        A region of another size than the image.
    """
    img = np.asarray(side_rgb)
    if roi.mask is None:
        return img
    if roi.mask.shape != img.shape[:2]:
        raise ValueError(f"the region is {roi.mask.shape}, the image {img.shape[:2]}")
    return img, roi.mask
