"""Named arm configurations of the simulated cell, for demos, tests and benchmarks.

The three viewpoints of the chapter's section 4.1 (one on top of the object, two on its
sides) are computed here from forward kinematics (eq. 20) with a small local least-squares
solve on the three pitch joints; this is a helper for fixed set-ups, not the product's
inverse kinematics (``robot.kinematics.ik``).
"""

from __future__ import annotations

import itertools
import math

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import least_squares

from robot.aiming import aimed_flange_pose
from robot.errors import Unreachable
from robot.kinematics import fk
from robot.model import ASEA, ArmModel, check_joints
from robot.sim.world import ConveyorSpec
from robot.trajectory import JointTrajectory, plan_joint_move

__all__ = ["VIEWS", "flange_config", "standard_configurations", "standard_moves", "viewpoint"]

#: Viewpoints on an object: approach angle phi (from the horizontal, eq. 20) and the side.
VIEWS = {"top": -90.0, "inner": -60.0, "outer": -120.0}


def flange_config(
    position: ArrayLike,
    phi_rad: float,
    *,
    q5: float = 0.0,
    seed: ArrayLike | None = None,
    model: ArmModel = ASEA,
) -> NDArray[np.float64]:
    """Joints putting the flange at ``position`` (base frame) with approach angle ``phi_rad``.

    q1 points the arm plane at the target; q2, q3, q4 come from a least-squares fit of
    eq. 20 started at ``seed`` (default ``model.q_ready``, elbow up).  Raises
    :class:`~robot.errors.Unreachable` when the fit misses by more than 0.1 mm or leaves
    the joint ranges.
    """
    p = np.asarray(position, dtype=np.float64)
    q1 = math.atan2(p[1], p[0])
    q0 = np.asarray(model.q_ready if seed is None else seed, dtype=np.float64)

    def residual(x: NDArray[np.float64]) -> NDArray[np.float64]:
        q = np.array([q1, x[0], x[1], x[2], q5])
        f = fk(q, model)
        return np.concatenate([f[:3] - p, [math.cos(phi_rad) - f[3], math.sin(phi_rad) - f[4]]])

    sol = least_squares(
        residual,
        q0[1:4],
        bounds=(model.lower[1:4], model.upper[1:4]),
        xtol=1e-14,
        ftol=1e-14,
        gtol=1e-14,
    )
    q = np.array([q1, *sol.x, q5])
    miss = float(np.abs(residual(sol.x)).max())
    if miss > 1e-4 or not model.within_limits(q):
        raise Unreachable(
            f"no configuration puts the flange at {p.tolist()} with phi = {math.degrees(phi_rad):.1f} deg (miss {miss:.3g})"
        )
    return check_joints(q, model)


def viewpoint(
    target: ArrayLike,
    view: str,
    *,
    distance_m: float = 0.42,
    q5: float = 0.0,
    model: ArmModel = ASEA,
) -> NDArray[np.float64]:
    """Joints that aim the approach axis at ``target`` from ``distance_m`` away.

    ``view`` is ``"top"`` (straight down), ``"inner"`` (30 deg off vertical, from the arm's
    side) or ``"outer"`` (30 deg off vertical, from beyond the object).
    """
    if view not in VIEWS:
        raise ValueError(f"view must be one of {tuple(VIEWS)}, got {view!r}")
    t = np.asarray(target, dtype=np.float64)
    phi = math.radians(VIEWS[view])
    pose = aimed_flange_pose(t, phi_rad=phi, distance_m=distance_m)
    return flange_config(np.array(pose[:3]), phi, q5=q5, model=model)


def standard_configurations(
    conveyor: ConveyorSpec | None = None, model: ArmModel = ASEA
) -> dict[str, NDArray[np.float64]]:
    """Named configurations: home, the three station viewpoints, an upstream look, the table."""
    c = conveyor or ConveyorSpec()
    station = c.station_point + np.array([0.0, 0.0, 0.1])  # top of a typical object
    upstream = station + np.array([0.0, -0.45, 0.0])
    return {
        "home": np.array(model.q_home),
        "top": viewpoint(station, "top", model=model),
        # From the arm's side the elbow runs out of range closer than ~0.62 m (q3 > -126 deg).
        "inner": viewpoint(station, "inner", distance_m=0.65, model=model),
        "outer": viewpoint(station, "outer", model=model),
        "upstream": viewpoint(upstream, "top", model=model),
        "table": viewpoint(np.array([0.0, -0.85, 0.45]), "top", distance_m=0.5, model=model),
    }


def standard_moves(
    conveyor: ConveyorSpec | None = None, *, speed: float = 1.0, model: ArmModel = ASEA
) -> list[tuple[str, JointTrajectory]]:
    """A tour through :func:`standard_configurations` (each move starts where the last ended)."""
    cfg = standard_configurations(conveyor, model)
    tour = ["home", "top", "inner", "outer", "top", "upstream", "table", "home"]
    return [
        (f"{a}->{b}", plan_joint_move(cfg[a], cfg[b], speed=speed, model=model))
        for a, b in itertools.pairwise(tour)
    ]
