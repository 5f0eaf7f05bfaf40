"""The cell's world around the arm, as the backend sees it: the station, the belt, the bins.

A :class:`CellLayout` is what the inspection needs to know about where things are: the
inspection station on the surface parts lie on, the belt through it (when there is one),
and the sorting bins with the parts each takes.  The simulator provides its own
(:func:`robot.sim.layout.cell_layout`); a real cell describes its own in a layout file
(:func:`robot.layoutfile.load_layout`).  Neither the layout nor the conveyor
(:class:`robot.drivers.conveyor.Conveyor`) says where the objects truly are: that is a
:class:`TruthSource`, which only a simulated cell has and only evaluations read.

Frames and units: the robot's base frame, metres and radians.  The belt runs along base
``+y`` through the station.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "DEFAULT_STATION_XY_M",
    "DEFAULT_SURFACE_Z_M",
    "MAX_BINS",
    "BeltSpan",
    "Bin",
    "CellLayout",
    "TruthSource",
]

#: Where the station is unless a layout says otherwise: in front of the arm (``q1 = 0``)
#: at ``r = 0.8 m``, the surface 0.45 m high, so that parts 0.08-0.17 m tall have their
#: tops near the viewpoints' design point (``r = 0.8 m, z = 0.55 m``).
DEFAULT_STATION_XY_M = (0.8, 0.0)
DEFAULT_SURFACE_Z_M = 0.45
#: Most bins a layout may have.
MAX_BINS = 64
#: Farthest a station, a belt end or a bin may be from the base axis, metres (the arm
#: reaches about 1.5 m; anything farther is a typing error, not a place).
MAX_REACH_M = 3.0


def _finite(name: str, *values: float) -> None:
    for v in values:
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            raise ValueError(f"{name} must be finite numbers, got {values!r}")


@dataclass(frozen=True)
class Bin:
    """One sorting bin.

    Attributes
    ----------
    name : str
        A word (letters, digits, ``-``, ``_``), at most 64 characters.
    parts : tuple of str
        The parts sorted into it (the models' ``part``, else their name).
    drop_xyz_m : (float, float, float)
        Where the part is let go: the centre of the bin's opening at its rim, base frame.
    reject : bool
        The bin of unknown and failed parts (it takes no named part).
    size_m : float
        Outer side of its square footprint (drawn in the 3D view).
    yaw_rad : float
        Its turn about the vertical (drawn in the 3D view).
    """

    name: str
    parts: tuple[str, ...]
    drop_xyz_m: tuple[float, float, float]
    reject: bool = False
    size_m: float = 0.4
    yaw_rad: float = 0.0

    def __post_init__(self) -> None:
        n = self.name
        if (
            not isinstance(n, str)
            or not n
            or len(n) > 64
            or not all(c.isascii() and (c.isalnum() or c in "-_") for c in n)
        ):
            raise ValueError(f"a bin's name must be a word of letters, digits, '-', '_' "
                             f"(at most 64), got {n!r}")  # fmt: skip
        _finite(f"bin {n!r}: drop_xyz_m", *self.drop_xyz_m)
        if len(self.drop_xyz_m) != 3:
            raise ValueError(f"bin {n!r}: drop_xyz_m must be (x, y, z), got {self.drop_xyz_m!r}")
        x, y, z = self.drop_xyz_m
        if math.hypot(x, y) > MAX_REACH_M or not -1.0 <= z <= 2.5:
            raise ValueError(f"bin {n!r}: drop_xyz_m must lie within {MAX_REACH_M:g} m of the "
                             f"base axis, z in [-1, 2.5] m, got {self.drop_xyz_m!r}")  # fmt: skip
        _finite(f"bin {n!r}: size_m and yaw_rad", self.size_m, self.yaw_rad)
        if not 0.05 <= self.size_m <= 2.0:
            raise ValueError(f"bin {n!r}: size_m must be in [0.05, 2] m, got {self.size_m!r}")
        if self.reject and self.parts:
            raise ValueError(f"the reject bin {n!r} takes no named parts, got {self.parts!r}")
        if not self.reject and not self.parts:
            raise ValueError(f"bin {n!r} takes no part: give it parts or make it the reject bin")
        for p in self.parts:
            if not isinstance(p, str) or not p.strip() or len(p) > 128:
                raise ValueError(f"bin {n!r}: a part name must be 1..128 characters, got {p!r}")

    @property
    def drop_point(self) -> NDArray[np.float64]:
        """``drop_xyz_m`` as an array (3,), base frame."""
        return np.asarray(self.drop_xyz_m, dtype=np.float64)

    @property
    def centre_xy(self) -> tuple[float, float]:
        """Centre of its footprint (under the drop point)."""
        return (float(self.drop_xyz_m[0]), float(self.drop_xyz_m[1]))

    @property
    def rim_z_m(self) -> float:
        """Height of its rim (the drop point's)."""
        return float(self.drop_xyz_m[2])

    def corners_xy(self) -> NDArray[np.float64]:
        """Outer footprint corners, (4, 2), base frame."""
        h = self.size_m / 2.0
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        local = np.array([[-h, -h], [h, -h], [h, h], [-h, h]])
        return local @ np.array([[c, -s], [s, c]]).T + np.asarray(self.centre_xy)


@dataclass(frozen=True)
class BeltSpan:
    """The belt through the station, along base ``+y`` on the station's ``x``.

    Attributes
    ----------
    start_y_m, end_y_m : float
        Where parts come on and leave it.
    width_m : float
    """

    start_y_m: float
    end_y_m: float
    width_m: float

    def __post_init__(self) -> None:
        _finite("belt start_y_m, end_y_m, width_m", self.start_y_m, self.end_y_m, self.width_m)
        if not self.end_y_m > self.start_y_m:
            raise ValueError(f"belt end_y_m must exceed start_y_m, got start_y_m "
                             f"{self.start_y_m!r}, end_y_m {self.end_y_m!r}")  # fmt: skip
        if max(abs(self.start_y_m), abs(self.end_y_m)) > MAX_REACH_M:
            raise ValueError(f"the belt's ends must lie within {MAX_REACH_M:g} m of the base, "
                             f"got {self.start_y_m!r}, {self.end_y_m!r}")  # fmt: skip
        if not 0.05 <= self.width_m <= 2.0:
            raise ValueError(f"belt width_m must be in [0.05, 2] m, got {self.width_m!r}")

    @property
    def length_m(self) -> float:
        """From where parts come on to where they leave."""
        return self.end_y_m - self.start_y_m


@dataclass(frozen=True)
class CellLayout:
    """Where the station, the belt and the bins are (module docstring).

    Attributes
    ----------
    station_xy_m : (float, float)
        The inspection station on the surface, base frame.
    surface_z_m : float
        Height of the surface parts lie on at the station (the belt's).
    belt : BeltSpan or None
        The belt through the station; None for a fixed station (parts placed by hand).
    bins : tuple of Bin
        Sorting bins (empty: the cell does not sort); names distinct, each part in one
        bin, at most one reject bin.
    source : str
        Where it comes from, for messages (``simulator``, a layout file's path, ``default``).
    """

    station_xy_m: tuple[float, float] = DEFAULT_STATION_XY_M
    surface_z_m: float = DEFAULT_SURFACE_Z_M
    belt: BeltSpan | None = None
    bins: tuple[Bin, ...] = ()
    source: str = "default"

    def __post_init__(self) -> None:
        _finite("station_xy_m", *self.station_xy_m)
        _finite("surface_z_m", self.surface_z_m)
        if len(self.station_xy_m) != 2 or math.hypot(*self.station_xy_m) > MAX_REACH_M:
            raise ValueError(f"station_xy_m must be (x, y) within {MAX_REACH_M:g} m of the base "
                             f"axis, got {self.station_xy_m!r}")  # fmt: skip
        if not -1.0 <= self.surface_z_m <= 2.0:
            raise ValueError(f"surface_z_m must be in [-1, 2] m, got {self.surface_z_m!r}")
        if self.belt is not None and not (
            self.belt.start_y_m <= self.station_xy_m[1] <= self.belt.end_y_m
        ):
            raise ValueError(f"the station (y {self.station_xy_m[1]:g} m) must lie on the belt "
                             f"(y {self.belt.start_y_m:g}..{self.belt.end_y_m:g} m)")  # fmt: skip
        if len(self.bins) > MAX_BINS:
            raise ValueError(f"at most {MAX_BINS} bins, got {len(self.bins)}")
        names = [b.name for b in self.bins]
        if len(set(names)) != len(names):
            raise ValueError(f"bin names must be distinct, got {names}")
        seen: dict[str, str] = {}
        for b in self.bins:
            for p in b.parts:
                if p in seen:
                    raise ValueError(
                        f"part {p!r} is sorted into two bins: {seen[p]!r} and {b.name!r}"
                    )
                seen[p] = b.name
        if sum(b.reject for b in self.bins) > 1:
            rejects = [b.name for b in self.bins if b.reject]
            raise ValueError(f"at most one reject bin, got {rejects}")

    @property
    def station_point(self) -> NDArray[np.float64]:
        """The station on the surface, (3,), base frame."""
        return np.array([*self.station_xy_m, self.surface_z_m], dtype=np.float64)

    @property
    def belt_end_y_m(self) -> float | None:
        """Where parts leave the belt (None: no belt)."""
        return None if self.belt is None else self.belt.end_y_m

    def bin_for(self, part: str | None) -> Bin | None:
        """The bin that takes ``part``; else (and for ``None``: an unknown or failed part) the
        reject bin; None when there is neither."""
        if part is not None:
            for b in self.bins:
                if part in b.parts:
                    return b
        return next((b for b in self.bins if b.reject), None)

    def public(self) -> dict[str, Any]:
        """The layout for the API and the reports (metres)."""
        return {
            "source": self.source,
            "station_xy_m": list(self.station_xy_m),
            "surface_z_m": self.surface_z_m,
            "belt": None if self.belt is None else {
                "start_y_m": self.belt.start_y_m, "end_y_m": self.belt.end_y_m,
                "width_m": self.belt.width_m,
            },
            "bins": [{"name": b.name, "parts": list(b.parts), "drop_xyz_m": list(b.drop_xyz_m),
                      "reject": b.reject} for b in self.bins],
        }  # fmt: skip


@runtime_checkable
class TruthSource(Protocol):
    """Where the objects truly are: only a simulated cell knows.  Read by evaluations (an
    inspection row's ``truth``, the reports' confusion matrix, the benchmarks), never by a
    decision."""

    def object_near(self, point: NDArray[np.float64], back_m: float = 0.0) -> dict[str, Any] | None:
        """The object nearest ``point`` (base frame) when moved back ``back_m`` along the belt
        (its travel since an exposure): ``id``, ``name``, ``trainable``, ``T_base_obj`` (4x4
        list, moved back), ``yaw_rad``; None when there is no object."""
        ...
