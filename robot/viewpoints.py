"""Viewpoints of an inspection, planned from where the object was found (pure functions).

The chapter's cell (section 4.1) looks at each object from the top (viewpoint 1) and, when
the top view does not decide, from two sides about 30 deg off vertical (viewpoints 2 and
3): from the inner side (the camera between the column and the object, looking outwards)
and from the outer side (the camera beyond the object, looking back towards the column).
Here they are computed for the object's actual position instead of being fixed poses:

* the camera's optical axis is aimed at the centre of the object's top face (the footprint
  centre raised by ``aim_height_fraction`` of its height) from ``distance_m`` with
  :func:`robot.aiming.look_at`, the geometry the calibration planner shares
  (:func:`robot.aiming.aimed_flange_pose`), for the given camera mounting ``T_ee_cam``
  (the hand-eye result in the product, ``NOMINAL_T_EE_CAM`` before calibration);
* each candidate passes the closed-form IK within the joint ranges
  (:func:`robot.kinematics.ik`) and the collision model (:class:`robot.collision.
  CollisionWorld`: the cell's furniture plus a box round the object itself);
* a viewpoint that fails is replaced by the nearest reachable one.  A 5-DOF arm's views of
  a point lie in the vertical plane through the column and the point (up to the camera's
  offset from the approach axis), so the search runs over the signed tilt in that plane,
  which covers both azimuths the arm can look from (towards and away from the column), in
  order of the angle from the nominal direction, and over the distance within
  ``distance_range_m``, nearest to the nominal first.  The result says whether the nominal
  viewpoint was reached, how far in degrees the chosen one is from it and why.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robot.aiming import approach_axis, axis_angles, look_at
from robot.collision import Box, CollisionWorld
from robot.errors import Unreachable
from robot.model import ASEA, ArmModel

__all__ = [
    "VIEW_INDEX",
    "VIEW_NAMES",
    "Viewpoint",
    "ViewpointPlan",
    "plan_viewpoint",
    "plan_viewpoints",
]

#: Viewpoint names in the chapter's order and their numbers (1 top, 2 inner, 3 outer).
VIEW_NAMES = ("top", "inner", "outer")
VIEW_INDEX = {"top": 1, "inner": 2, "outer": 3}
#: Nominal camera-to-target distances, metres.  From the column's side the elbow (q3 >=
#: -126 deg) keeps the camera at least about 0.6 m from a point at the station.
NOMINAL_DISTANCE_M = {"top": 0.38, "inner": 0.62, "outer": 0.38}
#: Farthest a planned point may lie from the column axis, and its height range, metres.
_MAX_RADIUS_M = 1.6
_Z_RANGE_M = (0.0, 1.5)


@dataclass(frozen=True)
class Viewpoint:
    """One planned viewpoint.

    Attributes
    ----------
    index : int
        1 (top), 2 (inner side) or 3 (outer side).
    name : str
        ``"top"``, ``"inner"`` or ``"outer"``.
    q : ndarray of shape (5,)
        Joints within the ranges and clear of the collision model, radians.
    T_base_ee : ndarray of shape (4, 4)
        Flange pose.
    T_base_cam : ndarray of shape (4, 4)
        Camera pose (OpenCV frame) predicted with the given ``T_ee_cam``.
    target : ndarray of shape (3,)
        Point on the optical axis, base frame.
    distance_m : float
        Camera centre to target.
    tilt_deg, azimuth_deg : float
        Direction of the optical axis: angle from straight down and azimuth of its
        horizontal part (the azimuth is 0 for a vertical axis).
    reached_nominal : bool
        True when the nominal direction and distance were reached.
    deviation_deg : float
        Angle between the chosen and the nominal viewing directions.
    reason : str
        Empty for a nominal viewpoint; else why the nominal one failed and what replaced it.
    """

    index: int
    name: str
    q: NDArray[np.float64]
    T_base_ee: NDArray[np.float64]
    T_base_cam: NDArray[np.float64]
    target: NDArray[np.float64]
    distance_m: float
    tilt_deg: float
    azimuth_deg: float
    reached_nominal: bool
    deviation_deg: float
    reason: str

    def as_dict(self) -> dict[str, object]:
        """JSON-friendly form (joints in radians, angles in degrees)."""
        return {
            "index": self.index,
            "name": self.name,
            "q": [float(v) for v in self.q],
            "target": [float(v) for v in self.target],
            "distance_m": self.distance_m,
            "tilt_deg": self.tilt_deg,
            "azimuth_deg": self.azimuth_deg,
            "reached_nominal": self.reached_nominal,
            "deviation_deg": self.deviation_deg,
            "reason": self.reason,
        }


@dataclass(frozen=True)
class ViewpointPlan:
    """The viewpoints of one object, in the order asked for."""

    target: NDArray[np.float64]
    views: tuple[Viewpoint, ...]

    def by_name(self, name: str) -> Viewpoint:
        """The viewpoint called ``name`` (``KeyError`` if it was not planned)."""
        for v in self.views:
            if v.name == name:
                return v
        raise KeyError(name)


def _check_point(point: ArrayLike, height: float | None, fraction: float) -> NDArray[np.float64]:
    try:
        p = np.asarray(point, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise ValueError(f"point must be 3 numbers (x, y, z) in metres, got {point!r}") from None
    if p.shape != (3,) or not np.isfinite(p).all():
        raise ValueError(f"point must be 3 finite numbers (x, y, z) in metres, got {point!r}")
    r = math.hypot(p[0], p[1])
    if r > _MAX_RADIUS_M or not _Z_RANGE_M[0] <= p[2] <= _Z_RANGE_M[1]:
        raise ValueError(
            f"point {np.round(p, 4).tolist()} m is outside the arm's workspace "
            f"(radius <= {_MAX_RADIUS_M} m, z in {list(_Z_RANGE_M)} m)"
        )
    if height is not None and (
        isinstance(height, bool) or not isinstance(height, int | float) or not 0.0 < height <= 0.5
    ):
        raise ValueError(f"object_height_m must be in (0, 0.5] m or None, got {height!r}")
    if isinstance(fraction, bool) or not (
        isinstance(fraction, int | float) and 0.0 <= fraction <= 1.0
    ):
        raise ValueError(f"aim_height_fraction must be in [0, 1], got {fraction!r}")
    return p


def _signed_tilts(nominal_deg: float, step_deg: float, max_dev_deg: float) -> list[float]:
    """Signed tilts (> 0: camera on the column's side) ordered by distance from nominal."""
    out = [nominal_deg]
    k = 1
    while k * step_deg <= max_dev_deg + 1e-9:
        for s in (nominal_deg - k * step_deg, nominal_deg + k * step_deg):
            if -70.0 <= s <= 70.0:
                out.append(s)
        k += 1
    return out


def plan_viewpoint(
    point: ArrayLike,
    view: str,
    *,
    T_ee_cam: ArrayLike,
    object_height_m: float | None = None,
    object_radius_m: float = 0.18,
    aim_height_fraction: float = 1.0,
    world: CollisionWorld | None = None,
    distance_m: float | None = None,
    distance_range_m: tuple[float, float] = (0.30, 0.70),
    side_tilt_deg: float = 30.0,
    roll_rad: float = 0.0,
    tilt_step_deg: float = 2.5,
    max_deviation_deg: float = 60.0,
    distance_step_m: float = 0.04,
    seed: ArrayLike | None = None,
    model: ArmModel = ASEA,
) -> Viewpoint:
    """Plan one viewpoint (``"top"``, ``"inner"`` or ``"outer"``) of an object.

    Parameters
    ----------
    point : array_like of shape (3,)
        Where the object was found: its footprint centre on the belt, base frame, metres.
    view : {"top", "inner", "outer"}
    T_ee_cam : array_like of shape (4, 4)
        Camera mounting on the flange (hand-eye result; ``NOMINAL_T_EE_CAM`` uncalibrated).
    object_height_m : float, optional
        Height of the object; the target is raised by ``aim_height_fraction`` of it, and a
        box of half-width ``object_radius_m`` and this height round ``point`` joins the
        obstacles.  None: ``point`` is the target itself and the object is not modelled.
    object_radius_m : float
        Half-width of the object's obstacle box, metres.
    aim_height_fraction : float in [0, 1]
        1 aims at the centre of the top face (the chapter's station point, r = 0.8 m,
        z = 0.55 m, for a 0.1 m object), 0.5 at the centre of the volume.
    world : CollisionWorld, optional
        The cell's obstacles (default: the floor only).
    distance_m : float, optional
        Nominal camera-to-target distance (default :data:`NOMINAL_DISTANCE_M` of the view).
    distance_range_m : (float, float)
        Distances the replacement search may use.
    side_tilt_deg : float
        Nominal tilt of the side views from vertical.
    roll_rad : float
        Roll q5 of the flange (turns the image about the optical axis).
    tilt_step_deg, max_deviation_deg, distance_step_m : float
        Grid of the replacement search and the largest deviation accepted.
    seed : array_like of shape (5,), optional
        IK seed (default ``model.q_ready``).
    model : ArmModel

    Returns
    -------
    Viewpoint

    Raises
    ------
    ValueError
        Non-finite or out-of-workspace point, bad height, view name or search parameters.
    Unreachable
        No viewpoint within ``max_deviation_deg`` of the nominal is reachable and clear.
    """
    if view not in VIEW_INDEX:
        raise ValueError(f"view must be one of {VIEW_NAMES}, got {view!r}")
    p = _check_point(point, object_height_m, aim_height_fraction)
    d_lo, d_hi = distance_range_m
    d_nom = NOMINAL_DISTANCE_M[view] if distance_m is None else distance_m
    if not (0.05 < d_lo <= d_hi <= 2.0) or not (math.isfinite(d_nom) and d_lo <= d_nom <= d_hi):
        raise ValueError(
            f"need 0.05 < distance_range_m[0] <= distance_m <= distance_range_m[1] <= 2 m, "
            f"got range {distance_range_m!r} and distance {d_nom!r}"
        )
    for name, v, lo, hi in (
        ("side_tilt_deg", side_tilt_deg, 0.0, 60.0),
        ("tilt_step_deg", tilt_step_deg, 0.1, 30.0),
        ("max_deviation_deg", max_deviation_deg, 0.0, 120.0),
        ("distance_step_m", distance_step_m, 0.005, 0.5),
        ("object_radius_m", object_radius_m, 0.0, 0.5),
    ):
        if not (math.isfinite(v) and lo <= v <= hi):
            raise ValueError(f"{name} must be in [{lo}, {hi}], got {v!r}")
    if not (math.isfinite(roll_rad) and abs(roll_rad) <= math.pi):
        raise ValueError(f"roll_rad must be in [-pi, pi], got {roll_rad!r}")
    h = 0.0 if object_height_m is None else float(object_height_m)
    target = p + np.array([0.0, 0.0, h * float(aim_height_fraction)])
    obstacles = world or CollisionWorld(model=model)
    if object_height_m is not None:
        r = float(object_radius_m)
        obstacles = obstacles.with_boxes(
            Box("object", (p[0] - r, p[1] - r, p[2]), (p[0] + r, p[1] + r, p[2] + h))
        )
    s_nom = {"top": 0.0, "inner": side_tilt_deg, "outer": -side_tilt_deg}[view]
    az_t = math.atan2(target[1], target[0])
    nominal_dir = approach_axis(az_t, math.radians(-90.0 + s_nom))
    n_steps = int((d_hi - d_lo) / distance_step_m + 1e-9)
    others = sorted(
        {
            round(d, 9)
            for k in range(1, n_steps + 1)
            for d in (d_nom - k * distance_step_m, d_nom + k * distance_step_m)
            if d_lo - 1e-9 <= d <= d_hi + 1e-9
        },
        key=lambda d: (abs(d - d_nom), d),
    )
    dists = [d_nom, *others]
    first_failure = ""
    for s in _signed_tilts(s_nom, tilt_step_deg, max_deviation_deg):
        for d in dists:
            try:
                aimed = look_at(
                    target,
                    phi_rad=math.radians(-90.0 + s),
                    distance_m=d,
                    T_ee_cam=T_ee_cam,
                    roll_rad=roll_rad,
                    seed=seed,
                    model=model,
                )
            except Unreachable as e:
                why = f"is unreachable ({e.detail})"
            else:
                contacts = obstacles.contacts(aimed.q)
                if not contacts:
                    z = aimed.T_base_cam[:3, 2]
                    dev = math.degrees(math.acos(max(-1.0, min(1.0, float(z @ nominal_dir)))))
                    tilt, az = axis_angles(z)
                    nominal = s == s_nom and d == d_nom
                    reason = (
                        ""
                        if nominal
                        else (
                            f"nominal {view} view (tilt {abs(s_nom):.1f} deg, {d_nom:.3f} m) "
                            f"{first_failure}; replaced by tilt {abs(s):.1f} deg "
                            f"{'from the column side' if s > 0 else 'from beyond' if s < 0 else 'vertical'}"
                            f" at {d:.3f} m"
                        )
                    )
                    return Viewpoint(
                        VIEW_INDEX[view],
                        view,
                        aimed.q,
                        aimed.T_base_ee,
                        aimed.T_base_cam,
                        target,
                        aimed.distance_m,
                        math.degrees(tilt),
                        math.degrees(az),
                        nominal,
                        dev,
                        reason,
                    )
                why = "collides (" + "; ".join(str(c) for c in contacts[:3]) + ")"
            if not first_failure:
                first_failure = why
    raise Unreachable(
        f"no {view} viewpoint of {np.round(target, 4).tolist()} m within "
        f"{max_deviation_deg:g} deg of the nominal and {list(distance_range_m)} m: the "
        f"nominal one {first_failure}"
    )


def plan_viewpoints(
    point: ArrayLike,
    *,
    T_ee_cam: ArrayLike,
    views: tuple[str, ...] = VIEW_NAMES,
    **options: object,
) -> ViewpointPlan:
    """Plan the viewpoints ``views`` (default top, inner, outer) of an object at ``point``
    (the chapter's three viewpoints, section 4.1).

    Parameters
    ----------
    point : array_like of shape (3,)
        The object's footprint centre on the belt, base frame, metres.
    T_ee_cam : array_like of shape (4, 4)
        Camera mounting on the flange.
    views : tuple of {"top", "inner", "outer"}
        The views to plan, each at most once.
    **options
        Those of :func:`plan_viewpoint`; each view is planned independently.

    Returns
    -------
    ViewpointPlan

    Raises
    ------
    ValueError, Unreachable
        As :func:`plan_viewpoint`, for the first view that fails.
    """
    if not views or any(v not in VIEW_INDEX for v in views) or len(set(views)) != len(views):
        raise ValueError(f"views must be distinct names from {VIEW_NAMES}, got {views!r}")
    planned = tuple(
        plan_viewpoint(point, v, T_ee_cam=T_ee_cam, **options)  # type: ignore[arg-type]
        for v in views
    )
    return ViewpointPlan(planned[0].target, planned)
