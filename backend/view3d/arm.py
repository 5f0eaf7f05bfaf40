"""Poses of the arm's drawn parts, from the robot model (no constants of its own)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robot.kinematics import T_base_ee, joint_positions
from robot.model import ArmModel

__all__ = ["LinkShape", "arm_shapes", "link_poses"]


@dataclass(frozen=True)
class LinkShape:
    """A drawn part: a cylinder or box along the local +x axis from the part's frame origin.

    Attributes
    ----------
    name : str
        Scene name.
    kind : str
        ``"cylinder"`` or ``"box"``.
    length_m, width_m : float
        Extent along the link and across it.
    color : tuple of 3 ints
        RGB.
    """

    name: str
    kind: str
    length_m: float
    width_m: float
    color: tuple[int, int, int]


def arm_shapes(model: ArmModel) -> list[LinkShape]:
    """The parts, in the order :func:`link_poses` returns their frames."""
    orange = (230, 120, 30)
    grey = (90, 90, 100)
    return [
        LinkShape("column", "cylinder", model.L1, 0.20, grey),
        LinkShape("upper_arm", "box", model.L2, 0.12, orange),
        LinkShape("forearm", "box", model.L3, 0.10, orange),
        LinkShape("wrist", "cylinder", model.L45, 0.07, grey),
    ]


def _rot_zy(q1: float, pitch: float) -> NDArray[np.float64]:
    """Rz(q1) @ Ry(-pitch): the local x axis points along a link pitched up by ``pitch``."""
    c1, s1 = np.cos(q1), np.sin(q1)
    cp, sp = np.cos(pitch), np.sin(pitch)
    Rz = np.array([[c1, -s1, 0.0], [s1, c1, 0.0], [0.0, 0.0, 1.0]])
    Ry = np.array([[cp, 0.0, -sp], [0.0, 1.0, 0.0], [sp, 0.0, cp]])
    return Rz @ Ry


def link_poses(q: ArrayLike, model: ArmModel) -> list[NDArray[np.float64]]:
    """``T_base_part`` for each part of :func:`arm_shapes`, then ``T_base_ee`` last."""
    qa = np.asarray(q, dtype=np.float64)
    pts = joint_positions(qa, model)
    q1, q2, q3, q4 = qa[:4]
    pitches = [np.pi / 2.0, q2, q2 + q3, q2 + q3 + q4]  # column points straight up
    starts = [pts[0], pts[1], pts[2], pts[3]]
    out = []
    for start, pitch in zip(starts, pitches, strict=True):
        T = np.eye(4)
        T[:3, :3] = _rot_zy(q1, pitch)
        T[:3, 3] = start
        out.append(T)
    out.append(T_base_ee(qa, model))
    return out
