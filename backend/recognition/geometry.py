"""A taught part's height, measured from the teach's images (what the pick needs).

First from the top views' features (:func:`height_from_features`): the teach takes the top
view at three camera rolls, and the camera sits off the flange's axis, so the rolls see the
object from camera places about 90 mm apart; the features matched between them are
triangulated (:func:`vision.pose.structure.triangulate_heights`, the same guided
matching the pose uses) and the part's height is a high percentile of their heights: the
highest textured surface, where the suction cup seals.  Where too few features are
triangulated (a part with a plain top), from the silhouettes (:func:`measure_height`):

The teach sees the object from the top (viewpoint 1) and from the side views (2 inner,
3 outer: 30 deg off vertical), each with its segmented region and the camera pose of the
shot.  The object is modelled as a vertical prism over its footprint (the top view's
region back-projected onto the plane of its top face): a side view's silhouette pixel is
explained by a prism of height ``h`` when its viewing ray passes over the footprint at some
height between the belt and ``h``.  The lowest height at which a ray is over the footprint
is therefore the least ``h`` that pixel needs; for a camera looking down at the object, the
silhouette's far outline (the top face's far edge) needs the whole height, every other
pixel less.  Each side view's height is a high percentile of those needs over its region
(a lower bound for a part narrower at the top than its footprint, exact for a prism), and
the part's height the largest of the side views' (silhouette constraints as in the visual
hull; Laurentini, "The visual hull concept for silhouette-based image understanding", IEEE
PAMI 16(2), 1994).  The footprint is taken again on the plane of the height found
(starting on the belt's plane, where the footprint is widest and the heights least) until
the two agree.  The pick starts its guarded descent a margin above this height, so an
underestimate within the margin costs nothing.

A 2d model is taught from the top only; its teach takes one side view more, used for this
measurement alone (:mod:`backend.recognition.teach`).  When no side view gives a height
(no region, rays that never cross the footprint), the measurement says why and the model
keeps no height: the console then asks the engineer for it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from vision.camera import PinholeCamera
from vision.errors import InvalidInput
from vision.features.types import Features

__all__ = ["HeightMeasurement", "Silhouette", "TopShot", "height_from_features", "measure_height"]

#: Tallest part the measurement looks for, metres (the models' bound, MAX_HEIGHT_M).
MAX_HEIGHT_M = 0.5
#: Lowest height the measurement reports, metres (below it the part is a sheet the cup
#: cannot be told apart from the belt by silhouettes).
MIN_HEIGHT_M = 0.005
#: Height step along each viewing ray, metres.
STEP_M = 0.001
#: Footprint raster cell, metres.
CELL_M = 0.001
#: Most silhouette pixels used per side view (a regular subsample of the region).
MAX_PIXELS = 6000
#: Percentile of the side pixels' needed heights taken as the height (the far outline's
#: pixels are few; the top one per cent are dropped as segmentation noise).
PERCENTILE = 99.0
#: Fewest triangulated features for a height from the features.
MIN_FEATURES = 8
#: Percentile of the triangulated features' heights taken as the part's height.
FEATURE_PERCENTILE = 99.0
#: Largest disagreement of two side views' heights for the measurement to be trusted, m
#: (beyond it one region is wrong: a shadow or a neighbour taken for the part).
MAX_SPREAD_M = 0.05


@dataclass(frozen=True, eq=False)
class Silhouette:
    """One shot of the teach: the object's region and where the camera was.

    Attributes
    ----------
    mask : ndarray of bool, shape (H, W)
        The object's region.
    T_base_cam : ndarray of shape (4, 4)
        Camera pose of the shot, base frame (OpenCV convention, +z forward).
    """

    mask: NDArray[np.bool_]
    T_base_cam: NDArray[np.float64]


@dataclass(frozen=True)
class HeightMeasurement:
    """The result of :func:`measure_height`.

    Attributes
    ----------
    height_m : float or None
        The part's height above the belt, metres; None when it could not be measured.
    per_view_m : tuple of float
        The height each side view gave (metres), in the order given.
    footprint_m : tuple of float
        Width and length of the footprint's bounding box on the top face's plane, metres.
    note : str
        How it was measured, or why it could not be.
    """

    height_m: float | None
    per_view_m: tuple[float, ...]
    footprint_m: tuple[float, float]
    note: str
    method: str = "silhouettes"
    """``features`` (triangulated top-view features) or ``silhouettes``."""

    def public(self) -> dict[str, object]:
        """JSON form (millimetres, as the console shows it)."""
        return {
            "height_mm": None if self.height_m is None else round(self.height_m * 1e3, 1),
            "per_view_mm": [round(h * 1e3, 1) for h in self.per_view_m],
            "footprint_mm": [round(v * 1e3, 1) for v in self.footprint_m],
            "method": self.method,
            "note": self.note,
        }


@dataclass(frozen=True, eq=False)
class TopShot:
    """A taught top view's features and where its camera was.

    Attributes
    ----------
    features : Features
        The view's features (pixels of the trained image, inside the object's region).
    T_base_cam : ndarray of shape (4, 4)
        Camera pose of the shot, base frame.
    """

    features: Features
    T_base_cam: NDArray[np.float64]


def height_from_features(
    shots: Sequence[TopShot],
    camera: PinholeCamera,
    *,
    surface_z_m: float,
    max_height_m: float = MAX_HEIGHT_M,
) -> HeightMeasurement:
    """The part's height from the features of top views taken from different camera places
    with the object still (module docstring): ``height_m`` None, with the reason, when fewer
    than :data:`MIN_FEATURES` are triangulated.

    Parameters
    ----------
    shots : sequence of TopShot
        Two to 24 top views of one teach round (the object did not move between them).
    camera : PinholeCamera
        The camera model the views were taken with.
    surface_z_m : float
        Height of the belt surface in the base frame, metres.
    max_height_m : float
        Tallest height looked for, metres (kept below the lowest camera).
    """
    from vision.pose.structure import TaughtTopView, triangulate_heights

    if not 2 <= len(shots) <= 24:
        raise InvalidInput(f"shots must hold 2 to 24 top views, got {len(shots)}")
    if not (isinstance(surface_z_m, int | float) and math.isfinite(surface_z_m)):
        raise InvalidInput(f"surface_z_m must be a finite number, got {surface_z_m!r}")
    Ts = [np.asarray(s.T_base_cam, dtype=np.float64) for s in shots]
    if any(T.shape != (4, 4) or not np.isfinite(T).all() for T in Ts):
        raise InvalidInput("every T_base_cam must be a finite 4x4 matrix")
    lowest_cam = min(float(T[2, 3]) for T in Ts) - surface_z_m
    top = min(max_height_m, lowest_cam - 0.05)
    if top <= MIN_HEIGHT_M:
        return HeightMeasurement(None, (), (0.0, 0.0), "the cameras are not above the belt",
                                 "features")  # fmt: skip
    T_obj = np.eye(4)
    T_obj[2, 3] = surface_z_m
    views = [
        TaughtTopView(k, s.features, T, T_obj)
        for k, (s, T) in enumerate(zip(shots, Ts, strict=True))
    ]
    got = triangulate_heights(
        views, camera=camera, z_floor_m=surface_z_m, z_top_m=surface_z_m + top
    )
    z = np.concatenate([v[np.isfinite(v)] for v in got.by_view.values()]) - surface_z_m
    if len(z) < MIN_FEATURES:
        return HeightMeasurement(None, (), (0.0, 0.0),
                                 f"{len(z)} feature(s) triangulated from the top views (fewer "
                                 f"than {MIN_FEATURES})", "features")  # fmt: skip
    h = float(np.percentile(z, FEATURE_PERCENTILE))
    if h < MIN_HEIGHT_M:
        return HeightMeasurement(None, (), (0.0, 0.0), "the features lie on the belt", "features")
    return HeightMeasurement(min(h, top), (), (0.0, 0.0),
                             f"{len(z)} features triangulated from {len(shots)} top views, "
                             f"median {np.median(z) * 1e3:.0f} mm", "features")  # fmt: skip


def _rays(
    px: NDArray[np.float64], camera: PinholeCamera, T_base_cam: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Undistorted viewing rays (N, 3) of pixels ``px`` (N, 2), base frame (eq. 2-4)."""
    pts = np.asarray(px, dtype=np.float64).reshape(-1, 1, 2)
    norm = cv2.undistortPoints(pts, camera.K, np.asarray(camera.dist, dtype=np.float64))
    rays = np.concatenate([norm.reshape(-1, 2), np.ones((len(pts), 1))], axis=1)
    return rays @ T_base_cam[:3, :3].T


def _check(sil: Silhouette, what: str) -> tuple[NDArray[np.bool_], NDArray[np.float64]]:
    mask = np.asarray(sil.mask)
    T = np.asarray(sil.T_base_cam, dtype=np.float64)
    if mask.ndim != 2 or mask.size == 0 or mask.size > 4096 * 4096:
        raise InvalidInput(f"{what}: mask must be a 2D image of at most 4096 x 4096 pixels")
    if T.shape != (4, 4) or not np.isfinite(T).all():
        raise InvalidInput(f"{what}: T_base_cam must be a finite 4x4 matrix")
    return mask.astype(bool), T


@dataclass(frozen=True, eq=False)
class _Footprint:
    """The footprint rasterised on the base frame's xy plane (``CELL_M`` cells)."""

    grid: NDArray[np.bool_]
    x0: float
    y0: float

    def contains(self, xy: NDArray[np.float64]) -> NDArray[np.bool_]:
        ix = np.floor((xy[..., 0] - self.x0) / CELL_M).astype(np.int64)
        iy = np.floor((xy[..., 1] - self.y0) / CELL_M).astype(np.int64)
        h, w = self.grid.shape
        ok = (ix >= 0) & (ix < w) & (iy >= 0) & (iy < h)
        out = np.zeros(xy.shape[:-1], dtype=bool)
        out[ok] = self.grid[iy[ok], ix[ok]]
        return out


def _footprint(
    mask: NDArray[np.bool_], camera: PinholeCamera, T: NDArray[np.float64], z_m: float
) -> _Footprint | None:
    """The top view's region back-projected onto the plane ``z = z_m`` (its outer outlines
    filled), or None when it has none."""
    contours, _ = cv2.findContours(mask.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    contours = [c for c in contours if len(c) >= 3]
    if not contours:
        return None
    rays = [_rays(c.reshape(-1, 2).astype(np.float64), camera, T) for c in contours]
    polys = []
    for d in rays:
        if np.any(d[:, 2] >= -1e-6):
            return None  # a ray of the top view that does not go down to the plane
        s = (z_m - T[2, 3]) / d[:, 2]
        polys.append(T[:3, 3][None, :2] + s[:, None] * d[:, :2])
    allp = np.concatenate(polys)
    x0, y0 = allp.min(axis=0) - 2 * CELL_M
    x1, y1 = allp.max(axis=0) + 2 * CELL_M
    w, h = math.ceil((x1 - x0) / CELL_M) + 1, math.ceil((y1 - y0) / CELL_M) + 1
    if w * h > 4_000_000:  # more than 2 m x 2 m: not an object at the station
        return None
    grid = np.zeros((h, w), np.uint8)
    pix = [np.round((p - (x0, y0)) / CELL_M).astype(np.int32) for p in polys]
    cv2.fillPoly(grid, pix, 1)
    return _Footprint(grid.astype(bool), float(x0), float(y0))


def _needed_heights(
    sil_mask: NDArray[np.bool_],
    T: NDArray[np.float64],
    camera: PinholeCamera,
    foot: _Footprint,
    surface_z_m: float,
    max_height_m: float,
) -> NDArray[np.float64]:
    """For each (subsampled) silhouette pixel whose ray passes over the footprint below
    ``max_height_m``: the lowest height above the belt at which it does (module docstring)."""
    ys, xs = np.nonzero(sil_mask)
    if len(xs) == 0:
        return np.zeros(0)
    step = max(1, math.ceil(len(xs) / MAX_PIXELS))
    px = np.stack([xs[::step], ys[::step]], axis=1).astype(np.float64)
    d = _rays(px, camera, T)
    down = d[:, 2] < -1e-6
    d = d[down]
    c = T[:3, 3]
    heights = np.arange(0.0, max_height_m + STEP_M / 2, STEP_M)
    out = np.full(len(d), np.nan)
    # In blocks of rays, so the (rays x heights) points stay a few million.
    block = max(1, 2_000_000 // len(heights))
    for k in range(0, len(d), block):
        dk = d[k : k + block]
        s = (surface_z_m + heights[None, :] - c[2]) / dk[:, 2:3]  # (n, m) ray parameters
        xy = c[None, None, :2] + s[:, :, None] * dk[:, None, :2]
        inside = foot.contains(xy) & (s > 0)
        any_in = inside.any(axis=1)
        first = np.argmax(inside, axis=1)
        out[k : k + block] = np.where(any_in, heights[first], np.nan)
    return out[np.isfinite(out)]


def measure_height(
    top: Silhouette,
    sides: Sequence[Silhouette],
    camera: PinholeCamera,
    *,
    surface_z_m: float,
    max_height_m: float = MAX_HEIGHT_M,
    iterations: int = 8,
) -> HeightMeasurement:
    """Measure a part's height from its top view's and side views' regions (module docstring).

    Parameters
    ----------
    top : Silhouette
        The top view (camera looking down at the object).
    sides : sequence of Silhouette
        Side views (1 to 4), each looking down at the object from one side.
    camera : PinholeCamera
        The camera model (``K``, ``dist``) the regions were taken with.
    surface_z_m : float
        Height of the belt surface in the base frame, metres.
    max_height_m : float
        Tallest height looked for, metres, in (0, 0.5].
    iterations : int
        Times the footprint is taken again on the plane of the height found (1..10).

    Returns
    -------
    HeightMeasurement
        ``height_m`` None (with the reason in ``note``) when no side view gives a height.
    """
    if not (isinstance(max_height_m, int | float) and 0.0 < max_height_m <= MAX_HEIGHT_M):
        raise InvalidInput(f"max_height_m must be in (0, {MAX_HEIGHT_M}] m, got {max_height_m!r}")
    if not (isinstance(surface_z_m, int | float) and math.isfinite(surface_z_m)):
        raise InvalidInput(f"surface_z_m must be a finite number, got {surface_z_m!r}")
    if isinstance(iterations, bool) or not isinstance(iterations, int) or not 1 <= iterations <= 10:
        raise InvalidInput(f"iterations must be an integer in 1..10, got {iterations!r}")
    if not 1 <= len(sides) <= 4:
        raise InvalidInput(f"sides must hold 1 to 4 side views, got {len(sides)}")
    top_mask, T_top = _check(top, "top")
    checked = [_check(s, f"side {k + 1}") for k, s in enumerate(sides)]
    if not top_mask.any():
        return HeightMeasurement(None, (), (0.0, 0.0), "the top view has no object region")
    # From the belt up: the footprint on the belt's plane is the widest (every needed
    # height the least), so the heights rise to the least consistent one, the part's.
    h = 0.0
    per: list[float] = []
    foot: _Footprint | None = None
    for _ in range(iterations):
        foot = _footprint(top_mask, camera, T_top, surface_z_m + h)
        if foot is None:
            return HeightMeasurement(None, (), (0.0, 0.0), "the top view's region does not "
                                     "project onto the belt")  # fmt: skip
        per = []
        for mask, T in checked:
            need = _needed_heights(mask, T, camera, foot, surface_z_m, max_height_m)
            if len(need) >= 20:
                per.append(float(np.percentile(need, PERCENTILE)))
        if not per:
            return HeightMeasurement(None, (), _extent(foot), "no side view's region lies "
                                     "over the top view's footprint")  # fmt: skip
        new = float(max(per))  # each view's need is a lower bound: the largest is the best
        if abs(new - h) < 0.5 * STEP_M:
            h = new
            break
        h = max(MIN_HEIGHT_M, new)
    assert foot is not None
    spread = max(per) - min(per)
    if h < MIN_HEIGHT_M:
        return HeightMeasurement(None, tuple(per), _extent(foot),
                                 f"the side views show less than {MIN_HEIGHT_M * 1e3:.0f} mm "
                                 "of height")  # fmt: skip
    if spread > MAX_SPREAD_M:
        return HeightMeasurement(None, tuple(per), _extent(foot),
                                 f"the side views disagree by {spread * 1e3:.0f} mm (more than "
                                 f"{MAX_SPREAD_M * 1e3:.0f} mm)")  # fmt: skip
    note = (f"from {len(per)} side view(s) over the top view's footprint"
            + (f", {spread * 1e3:.1f} mm apart" if len(per) > 1 else ""))  # fmt: skip
    return HeightMeasurement(min(h, max_height_m), tuple(per), _extent(foot), note)


def _extent(foot: _Footprint) -> tuple[float, float]:
    ys, xs = np.nonzero(foot.grid)
    if len(xs) == 0:
        return (0.0, 0.0)
    return (float(xs.max() - xs.min() + 1) * CELL_M, float(ys.max() - ys.min() + 1) * CELL_M)
