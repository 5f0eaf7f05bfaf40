"""A simple collision check of the arm against the cell: link capsules against boxes and the floor.

The arm is modelled as capsules round the segments of the kinematic chain
(:func:`robot.kinematics.joint_positions`: column, upper arm, forearm, wrist) plus capsules
fixed to the flange round the tools it carries (:class:`ToolCapsule`: the camera body and the
suction cup's tube, see :data:`DEFAULT_TOOL_CAPSULES`); the cell as axis-aligned boxes (table, conveyor,
a calibration board's slab) and the floor plane ``z = 0``.  A capsule is checked as a row
of spheres along its axis spaced at most half its radius apart; their union falls short of
the capsule's surface by at most ``r (1 - sqrt(1 - 1/16))``, about 3 % of the radius, which
the required clearance covers.

This is a planning guard (refuse candidate poses that come near the furniture), not a
certified safety function; the real cell's safety comes from its fences and the e-stop.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robot.kinematics import T_base_ee, joint_positions
from robot.model import ASEA, ArmModel

__all__ = [
    "DEFAULT_TOOL_CAPSULES",
    "ArmCapsules",
    "Box",
    "CollisionWorld",
    "Contact",
    "ToolCapsule",
    "box_distance",
]


@dataclass(frozen=True)
class Box:
    """An axis-aligned box in the base frame.

    Attributes
    ----------
    name : str
        Reported in :class:`Contact`.
    lower, upper : tuple of 3 floats
        Opposite corners, metres.
    """

    name: str
    lower: tuple[float, float, float]
    upper: tuple[float, float, float]

    def __post_init__(self) -> None:
        lo, hi = np.asarray(self.lower, float), np.asarray(self.upper, float)
        if lo.shape != (3,) or hi.shape != (3,) or not (hi >= lo).all():
            raise ValueError(
                f"box {self.name!r}: lower must be <= upper, got {self.lower!r}, {self.upper!r}"
            )

    @classmethod
    def around(cls, name: str, points: ArrayLike, *, pad_m: float = 0.0) -> Box:
        """The smallest box holding ``points`` (N, 3), grown by ``pad_m`` on every side."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        lo, hi = p.min(axis=0) - pad_m, p.max(axis=0) + pad_m
        return cls(name, tuple(float(v) for v in lo), tuple(float(v) for v in hi))  # type: ignore[arg-type]


def box_distance(points: ArrayLike, box: Box) -> NDArray[np.float64]:
    """Euclidean distance of ``points`` (N, 3) to ``box`` (0 inside), shape (N,)."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    lo, hi = np.asarray(box.lower), np.asarray(box.upper)
    d = np.maximum(np.maximum(lo - p, p - hi), 0.0)
    return np.linalg.norm(d, axis=1)


@dataclass(frozen=True)
class ToolCapsule:
    """A capsule fixed to the flange round a tool (flange frame ``ee``, metres).

    Attributes
    ----------
    name : str
        Reported in :class:`Contact` (``"camera"``, ``"cup"``).
    a_ee, b_ee : tuple of 3 floats
        End points of its axis in the flange frame.
    radius_m : float
        Its radius.
    """

    name: str
    a_ee: tuple[float, float, float]
    b_ee: tuple[float, float, float]
    radius_m: float

    def __post_init__(self) -> None:
        a, b = np.asarray(self.a_ee, float), np.asarray(self.b_ee, float)
        r = self.radius_m
        if (
            a.shape != (3,)
            or b.shape != (3,)
            or not (np.isfinite(a).all() and np.isfinite(b).all())
        ):
            raise ValueError(f"tool capsule {self.name!r}: end points must be 3 finite numbers")
        if not (isinstance(r, int | float) and math.isfinite(r) and 0.001 <= r <= 0.3):
            raise ValueError(
                f"tool capsule {self.name!r}: radius_m must be in [0.001, 0.3], got {r!r}"
            )


#: The eye-in-hand camera and the suction cup on the flange (the drawn tools of
#: :mod:`robot.sim.mjcf`, each grown by a few millimetres): the camera body (56 x 56 x 48 mm
#: box and its lens, 50 mm along ``+x_ee``) as a capsule of radius 42 mm along the approach
#: axis; the cup's bracket, tube and bellows (50 mm along ``-x_ee``, 8-10.5 mm radius) as a
#: capsule of radius 13 mm from the flange face to 25 mm short of the lip.  The last 25 mm
#: (bellows' end and lip, 15 mm radius) are left out: they touch the part being picked, and
#: the lip's own clearance to the furniture is the pick planner's (its ``press_m`` and grasp
#: height), not the arm's.
DEFAULT_TOOL_CAPSULES: tuple[ToolCapsule, ...] = (
    ToolCapsule("camera", (0.05, 0.0, -0.03), (0.05, 0.0, 0.03), 0.042),
    ToolCapsule("cup", (-0.05, 0.0, 0.0), (-0.05, 0.0, 0.095), 0.013),
)


@dataclass(frozen=True)
class ArmCapsules:
    """Radii of the arm's collision shapes, metres (outer envelope of the ASEA-class links).

    Attributes
    ----------
    column_m, upper_arm_m, forearm_m, wrist_m : float
        Capsule radii of the segments base-shoulder, shoulder-elbow, elbow-wrist and
        wrist-flange.
    tools : tuple of ToolCapsule
        Capsules round the tools on the flange (default: camera and suction cup).
    """

    column_m: float = 0.16
    upper_arm_m: float = 0.10
    forearm_m: float = 0.08
    wrist_m: float = 0.06
    tools: tuple[ToolCapsule, ...] = DEFAULT_TOOL_CAPSULES

    @property
    def radii(self) -> tuple[float, float, float, float]:
        """Capsule radii of the four segments, base first."""
        return (self.column_m, self.upper_arm_m, self.forearm_m, self.wrist_m)


@dataclass(frozen=True)
class Contact:
    """A shape of the arm too near an obstacle.

    Attributes
    ----------
    link : str
        ``"column"``, ``"upper_arm"``, ``"forearm"``, ``"wrist"`` or a tool's name
        (``"camera"``, ``"cup"``).
    obstacle : str
        The box's name or ``"floor"``.
    clearance_m : float
        Surface distance (negative: penetration).
    """

    link: str
    obstacle: str
    clearance_m: float

    def __str__(self) -> str:
        return f"{self.link} {self.clearance_m * 1e3:.0f} mm from the {self.obstacle}"


_LINKS = ("column", "upper_arm", "forearm", "wrist")


@dataclass(frozen=True)
class CollisionWorld:
    """Obstacles of a cell and the arm's collision shapes.

    Attributes
    ----------
    boxes : tuple of Box
        Furniture (and anything else the arm must keep clear of).
    floor_z_m : float
        Height of the floor plane; the column stands on it and is not checked against it.
    clearance_m : float
        Required gap between any arm shape and any obstacle.
    shapes : ArmCapsules
        The arm's radii.
    model : ArmModel
        Link lengths.
    """

    boxes: tuple[Box, ...] = ()
    floor_z_m: float = 0.0
    clearance_m: float = 0.02
    shapes: ArmCapsules = field(default_factory=ArmCapsules)
    model: ArmModel = ASEA

    def with_boxes(self, *extra: Box) -> CollisionWorld:
        """A copy with more obstacles."""
        return CollisionWorld(
            (*self.boxes, *extra), self.floor_z_m, self.clearance_m, self.shapes, self.model
        )

    def _spheres(self, q: NDArray[np.float64]) -> list[tuple[str, NDArray[np.float64], float]]:
        """Sample spheres covering each capsule (spacing <= radius / 2), then the tools'."""
        pts = joint_positions(q, self.model)
        out: list[tuple[str, NDArray[np.float64], float]] = []
        for k, (name, r) in enumerate(zip(_LINKS, self.shapes.radii, strict=True)):
            a, b = pts[k], pts[k + 1]
            n = max(2, math.ceil(float(np.linalg.norm(b - a)) / (0.5 * r)) + 1)
            t = np.linspace(0.0, 1.0, n)[:, None]
            out.append((name, a + t * (b - a), r))
        T = T_base_ee(q, self.model)
        for tool in self.shapes.tools:
            a = T[:3, :3] @ np.asarray(tool.a_ee) + T[:3, 3]
            b = T[:3, :3] @ np.asarray(tool.b_ee) + T[:3, 3]
            r = tool.radius_m
            n = max(2, math.ceil(float(np.linalg.norm(b - a)) / (0.5 * r)) + 1)
            t = np.linspace(0.0, 1.0, n)[:, None]
            out.append((tool.name, a + t * (b - a), r))
        return out

    def contacts(self, q: ArrayLike) -> list[Contact]:
        """Every arm shape nearer than ``clearance_m`` to an obstacle at joints ``q`` (5,)."""
        qa = np.asarray(q, dtype=np.float64)
        if qa.shape != (5,) or not np.isfinite(qa).all():
            raise ValueError(f"q must be 5 finite joint values, got {np.asarray(q).tolist()}")
        found: list[Contact] = []
        for name, centres, r in self._spheres(qa):
            if name != "column":
                gap = float(centres[:, 2].min()) - r - self.floor_z_m
                if gap < self.clearance_m:
                    found.append(Contact(name, "floor", gap))
            for box in self.boxes:
                gap = float(box_distance(centres, box).min()) - r
                if gap < self.clearance_m:
                    found.append(Contact(name, box.name, gap))
        return found

    def collides(self, q: ArrayLike) -> bool:
        """Whether any arm shape comes nearer than ``clearance_m`` to an obstacle."""
        return bool(self.contacts(q))

    def collides_many(self, qs: ArrayLike) -> NDArray[np.bool_]:
        """:meth:`collides` for each row of ``qs`` (N, 5), vectorised over the rows, the
        spheres and the boxes (the same spheres and test as :meth:`contacts`)."""
        qa = np.asarray(qs, dtype=np.float64).reshape(-1, 5)
        if not np.isfinite(qa).all():
            raise ValueError("qs must be finite joint values")
        out = np.zeros(len(qa), dtype=bool)
        if not len(qa):
            return out
        first = self._spheres(qa[0])
        counts = [len(c) for _, c, _ in first]
        radii = np.concatenate([np.full(n, r) for n, (_, _, r) in zip(counts, first, strict=True)])
        on_floor = np.concatenate(
            [np.full(n, name != "column") for n, (name, _, _) in zip(counts, first, strict=True)]
        )
        lo = np.array([b.lower for b in self.boxes]).reshape(-1, 3)
        hi = np.array([b.upper for b in self.boxes]).reshape(-1, 3)
        for i, q in enumerate(qa):
            c = np.concatenate([cs for _, cs, _ in (first if i == 0 else self._spheres(q))])
            if np.any((c[on_floor, 2] - radii[on_floor] - self.floor_z_m) < self.clearance_m):
                out[i] = True
                continue
            if len(lo):
                d = np.maximum(np.maximum(lo[None] - c[:, None], c[:, None] - hi[None]), 0.0)
                gap = np.sqrt((d * d).sum(axis=2)) - radii[:, None]
                out[i] = bool((gap < self.clearance_m).any())
        return out

    def path_contacts(
        self, q_from: ArrayLike, q_to: ArrayLike, *, step_rad: float = 0.05
    ) -> list[Contact]:
        """Contacts along the straight joint-space path (what a synchronised joint move
        follows), checked every ``step_rad`` of the largest joint change."""
        a, b = np.asarray(q_from, dtype=np.float64), np.asarray(q_to, dtype=np.float64)
        n = max(2, math.ceil(float(np.abs(b - a).max()) / step_rad) + 1)
        for t in np.linspace(0.0, 1.0, n):
            c = self.contacts(a + t * (b - a))
            if c:
                return c
        return []
