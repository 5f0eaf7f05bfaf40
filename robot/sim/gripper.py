"""The suction gripper of the simulated cell: the cup, when it seals, and what it carries.

The cup sits on the flange beside the camera, on the opposite side of the approach axis
(``T_ee_cup``: 50 mm along ``-x_ee``, its lip 120 mm past the flange face, pointing along
the approach axis), outside the camera's field of view (a test projects it).

Suction is a kinematic weld: while it is on and nothing is held, the cup *seals* on an
object when a ray from the cup's centre along its axis meets the object's mesh within
``seal_gap_m`` ahead of the lip or ``max_press_m`` behind it (the bellows' travel), on a
face whose normal is within ``max_tilt_deg`` of the cup's axis (a suction cup does not
seal on a steep face).  From then on the object's pose is the cup's times the fixed
``T_cup_obj`` found at sealing, and its mass, with the inertia of a solid box of its
bounding size, is added to a payload body on the flange, so that MuJoCo's dynamics load
the arm with it and the joint controller has to carry it (its computed-torque model reads
the same MuJoCo model: the payload is declared to the controller on gripping, as an
industrial controller's grip-load instruction does).  Suction off lets it go.

The catalogue gives no masses: :func:`payload_mass_kg` takes the bounding box's volume
at an effective density of :data:`EFFECTIVE_DENSITY_KG_M3` (hollow cast parts), which gives
about 3 kg for a wheel and 0.5-1 kg for the other parts, inside the ASEA IRB 6 class's
6 kg payload.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from robot.pick import T_EE_SUCTION_CUP
from robot.sim.catalogue import CATALOGUE

__all__ = [
    "DEFAULT_T_EE_CUP",
    "EFFECTIVE_DENSITY_KG_M3",
    "Landing",
    "SuctionCupSpec",
    "payload_inertia",
    "payload_mass_kg",
    "ray_to_object",
    "suction_point",
]

#: Mass per bounding-box volume of the catalogue's objects, kg/m^3 (an assumption).
EFFECTIVE_DENSITY_KG_M3 = 300.0


#: The cup's lip centre on the flange (z along the approach axis): the pick planner's tool.
DEFAULT_T_EE_CUP = T_EE_SUCTION_CUP


@dataclass(frozen=True)
class SuctionCupSpec:
    """The suction cup.

    Attributes
    ----------
    T_ee_cup : ndarray of shape (4, 4)
        Lip centre and axis in the flange frame (z pointing away from the flange).
    radius_m : float
        Lip radius.
    seal_gap_m : float
        Largest gap ahead of the lip at which suction still pulls the part on.
    max_press_m : float
        Largest compression of the bellows (the lip pressed into the part's surface).
    max_tilt_deg : float
        Largest angle between the surface normal and the cup axis that still seals.
    max_payload_kg : float
        Heaviest part the cup holds (heavier ones are not lifted).
    """

    T_ee_cup: NDArray[np.float64] = field(default_factory=lambda: DEFAULT_T_EE_CUP)
    radius_m: float = 0.015
    seal_gap_m: float = 0.004
    max_press_m: float = 0.012
    max_tilt_deg: float = 20.0
    max_payload_kg: float = 6.0

    def __post_init__(self) -> None:
        T = np.asarray(self.T_ee_cup, dtype=np.float64)
        if T.shape != (4, 4) or not np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-9):
            raise ValueError(f"T_ee_cup must be a 4x4 rigid transform, got {T.tolist()}")
        T = T.copy()
        T.setflags(write=False)
        object.__setattr__(self, "T_ee_cup", T)
        for name, lo, hi in (
            ("radius_m", 0.002, 0.1),
            ("seal_gap_m", 0.0, 0.05),
            ("max_press_m", 0.0, 0.05),
            ("max_tilt_deg", 0.0, 60.0),
            ("max_payload_kg", 0.01, 50.0),
        ):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and lo <= v <= hi):
                raise ValueError(f"{name} must be in [{lo}, {hi}], got {v!r}")


@functools.cache
def _triangles(name: str) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """All triangles of a catalogue entry in its object frame, (T, 3, 3), and unit normals."""
    tris = []
    for piece in CATALOGUE[name].geometry().pieces:
        m = piece.mesh
        tris.append(np.asarray(m.vertices, dtype=np.float64)[np.asarray(m.faces)])
    t = np.concatenate(tris)
    n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    norm = np.linalg.norm(n, axis=1)
    keep = norm > 1e-14
    return t[keep], n[keep] / norm[keep, None]


def ray_to_object(
    name: str, T_obj_ray: NDArray[np.float64], *, max_back_m: float
) -> tuple[float, NDArray[np.float64]] | None:
    """Nearest hit of a ray with a catalogue object's mesh (Moller-Trumbore, vectorised).

    Parameters
    ----------
    name : str
        Catalogue name.
    T_obj_ray : ndarray of shape (4, 4)
        The ray's origin (translation) and direction (z axis) in the object frame.
    max_back_m : float
        Hits up to this far *behind* the origin count too (a lip pressed into the surface).

    Returns
    -------
    (distance, normal) or None
        Signed distance along the ray to the first surface met from ``-max_back_m`` on
        (negative: behind the origin) and the face's unit normal in the object frame,
        oriented against the ray.
    """
    tris, normals = _triangles(name)
    d = T_obj_ray[:3, 2]
    o = T_obj_ray[:3, 3] - max_back_m * d
    e1 = tris[:, 1] - tris[:, 0]
    e2 = tris[:, 2] - tris[:, 0]
    pvec = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, pvec)
    ok = np.abs(det) > 1e-12
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    tvec = o - tris[:, 0]
    u = np.einsum("ij,ij->i", tvec, pvec) * inv
    qvec = np.cross(tvec, e1)
    v = (qvec @ d) * inv
    t = np.einsum("ij,ij->i", e2, qvec) * inv
    hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t >= 0)
    if not hit.any():
        return None
    i = int(np.flatnonzero(hit)[np.argmin(t[hit])])
    n = normals[i]
    if n @ d > 0:
        n = -n
    return float(t[i] - max_back_m), n


@functools.cache
def payload_mass_kg(name: str) -> float:
    """Mass of a catalogue object: bounding-box volume times the effective density."""
    b = CATALOGUE[name].geometry().bounds
    return float(np.prod(b[1] - b[0]) * EFFECTIVE_DENSITY_KG_M3)


def payload_inertia(name: str) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Centre of mass (object frame) and principal inertia (kg m^2) of a solid box the
    object's bounding size and :func:`payload_mass_kg` heavy."""
    b = CATALOGUE[name].geometry().bounds
    size = b[1] - b[0]
    m = payload_mass_kg(name)
    sx, sy, sz = size
    inertia = m / 12.0 * np.array([sy**2 + sz**2, sx**2 + sz**2, sx**2 + sy**2])
    return (b[0] + b[1]) / 2.0, inertia


@dataclass(frozen=True)
class Landing:
    """Where a released object came down (simulator truth, for evaluation only).

    Attributes
    ----------
    id : int
        The object's engine id.
    name : str
        Catalogue name.
    place : str
        A bin's name, ``"belt"`` (put back on the belt) or ``"floor"``.
    position : ndarray of shape (3,)
        Footprint centre at the moment of release, base frame.
    t_s : float
        Simulated time of the release.
    """

    id: int
    name: str
    place: str
    position: NDArray[np.float64]
    t_s: float

    def as_dict(self) -> dict[str, object]:
        """JSON-friendly form."""
        return {
            "id": self.id,
            "name": self.name,
            "place": self.place,
            "position_m": [float(v) for v in self.position],
            "t_s": self.t_s,
        }


def suction_point(
    name: str, spec: SuctionCupSpec | None = None, *, step_m: float = 0.01
) -> NDArray[np.float64]:
    """Where on the object's upper surface the cup is put: high, near the footprint centre.

    Rays straight down on a ``step_m`` grid over the footprint; a point qualifies when the
    centre ray and eight rays round the lip all meet faces within ``max_tilt_deg`` of
    horizontal and within 2 mm of the centre's height (the lip must rest on a flat patch).
    Among those, the one with the largest ``z - 0.5 r`` (height, less half the distance
    ``r`` from the footprint centre: high surfaces near the centre of mass) is chosen.
    This is the catalogue's geometry (the model's drawing), not a measurement.

    Returns
    -------
    ndarray of shape (3,)
        The point in the object frame.
    """
    if name not in CATALOGUE:
        raise ValueError(f"unknown catalogue name {name!r}")
    cup = spec or SuctionCupSpec()
    if not (math.isfinite(step_m) and 0.002 <= step_m <= 0.05):
        raise ValueError(f"step_m must be in [0.002, 0.05] m, got {step_m!r}")
    return _suction_point(name, cup.radius_m, cup.max_tilt_deg, float(step_m)).copy()


@functools.cache
def _suction_point(
    name: str, radius_m: float, max_tilt_deg: float, step_m: float
) -> NDArray[np.float64]:
    b = CATALOGUE[name].geometry().bounds
    top = float(b[1, 2]) + 0.05
    cos_tilt = math.cos(math.radians(max_tilt_deg))
    down = np.eye(4)
    down[:3, :3] = np.diag([1.0, -1.0, -1.0])
    ring = [
        (radius_m * math.cos(a), radius_m * math.sin(a))
        for a in np.linspace(0.0, 2.0 * math.pi, 8, endpoint=False)
    ]

    def height(x: float, y: float) -> float | None:
        down[:3, 3] = (x, y, top)
        hit = ray_to_object(name, down, max_back_m=0.0)
        if hit is None or hit[1][2] < cos_tilt:
            return None
        return top - hit[0]

    cands = []
    for x in np.arange(b[0, 0], b[1, 0] + 1e-9, step_m):
        for y in np.arange(b[0, 1], b[1, 1] + 1e-9, step_m):
            z = height(float(x), float(y))
            if z is not None:
                cands.append((z - 0.5 * math.hypot(x, y), float(x), float(y), z))
    for _, x, y, z in sorted(cands, reverse=True):
        rim = [height(x + dx, y + dy) for dx, dy in ring]
        if all(zr is not None and abs(zr - z) <= 0.002 for zr in rim):
            return np.array([x, y, z])
    raise ValueError(f"no surface of {name!r} where the suction cup seals")
