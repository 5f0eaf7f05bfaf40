"""The cell around the arm: floor, table, conveyor with its inspection station, and lights.

Layout (base frame, metres; chapter section 4.1: an assembly line at constant speed carrying
car wheels past the arm): the belt runs along +y on the line ``x = 0.8``, its surface at
``z = 0.45`` so that objects 0.08-0.17 m tall have their tops near the inspection station
at ``r = 0.8 m, z = 0.55 m``.  The station is where the belt crosses ``y = 0``, in front
of the arm (``q1 = 0``).  A table beside the arm (``q1 = -90 deg``) holds calibration
boards.

:class:`Conveyor` is the belt's state (pure Python, no MuJoCo): items ride it at the set
speed, continuously or indexing (stop when the next item reaches the station, dwell, go).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from robot.sim import textures as tx
from robot.sim.bins import BinSpec, add_bins, check_bins, default_bins
from robot.sim.builder import MjcfBuilder, fmt
from vision.errors import InvalidInput

__all__ = [
    "BeltItem",
    "Conveyor",
    "ConveyorSpec",
    "ConveyorState",
    "LightSpec",
    "WorldLayout",
    "add_world",
]

CONVEYOR_MODES = ("continuous", "index")


@dataclass(frozen=True)
class ConveyorSpec:
    """Where the belt is.

    Attributes
    ----------
    centre_x_m : float
        x of the belt's centre line in the base frame; the belt runs along +y.
    start_y_m, end_y_m : float
        Where items enter and leave.
    width_m : float
        Belt width.
    surface_z_m : float
        Height of the belt surface (the bottom of every item on it).
    station_y_m : float
        y of the inspection station.
    cleat_spacing_m : float
        Approximate spacing of the painted cross stripes that show the belt moving.
    """

    centre_x_m: float = 0.8
    start_y_m: float = -1.3
    end_y_m: float = 1.3
    width_m: float = 0.44
    surface_z_m: float = 0.45
    station_y_m: float = 0.0
    cleat_spacing_m: float = 0.3

    def __post_init__(self) -> None:
        if not self.end_y_m > self.start_y_m:
            raise ValueError(f"end_y_m must exceed start_y_m, got {self.start_y_m}, {self.end_y_m}")
        if not self.start_y_m <= self.station_y_m <= self.end_y_m:
            raise ValueError(f"station_y_m must lie on the belt, got {self.station_y_m}")

    @property
    def length_m(self) -> float:
        """Belt length from entry to exit."""
        return self.end_y_m - self.start_y_m

    @property
    def station_s_m(self) -> float:
        """Distance along the belt from its entry to the station."""
        return self.station_y_m - self.start_y_m

    def T_base_item(
        self, s_m: float, lateral_m: float = 0.0, yaw_rad: float = 0.0
    ) -> NDArray[np.float64]:
        """Pose of an item at ``s_m`` along the belt, ``lateral_m`` off its centre line
        (towards +x), turned by ``yaw_rad`` about z; origin on the belt surface."""
        c, s = math.cos(yaw_rad), math.sin(yaw_rad)
        T = np.eye(4)
        T[:2, :2] = [[c, -s], [s, c]]
        T[:3, 3] = (self.centre_x_m + lateral_m, self.start_y_m + s_m, self.surface_z_m)
        return T

    @property
    def station_point(self) -> NDArray[np.float64]:
        """The station on the belt surface, base frame."""
        return np.array([self.centre_x_m, self.station_y_m, self.surface_z_m])


@dataclass(frozen=True)
class LightSpec:
    """A light: ``kind`` is ``"directional"`` or ``"spot"``; intensity scales ``diffuse``."""

    name: str
    pos: tuple[float, float, float]
    dir: tuple[float, float, float]
    diffuse: float
    kind: str = "directional"
    castshadow: bool = False
    cutoff_deg: float = 45.0


@dataclass(frozen=True)
class WorldLayout:
    """Everything static in the cell besides the arm."""

    conveyor: ConveyorSpec = field(default_factory=ConveyorSpec)
    table_centre_xy: tuple[float, float] = (0.0, -0.85)
    table_size_xy: tuple[float, float] = (0.6, 0.5)
    table_top_z_m: float = 0.45
    lights: tuple[LightSpec, ...] = (
        LightSpec("ceiling", (0.4, 0.0, 3.0), (0.0, 0.0, -1.0), 0.45),
        LightSpec("station", (0.55, -0.35, 1.9), (0.25, 0.35, -1.45), 0.55, "spot", False, 40.0),
        LightSpec("fill", (-1.5, 1.5, 2.0), (1.0, -1.0, -1.0), 0.2),
    )
    ambient: float = 0.3
    #: Sorting bins beside the belt (:mod:`robot.sim.bins`).
    bins: tuple[BinSpec, ...] = field(default_factory=default_bins)

    def __post_init__(self) -> None:
        check_bins(tuple(self.bins))

    def bin(self, name: str) -> BinSpec:
        """The bin called ``name`` (``KeyError`` naming the bins if there is none)."""
        for b in self.bins:
            if b.name == name:
                return b
        raise KeyError(f"no bin {name!r}; bins: {', '.join(b.name for b in self.bins)}")

    @property
    def light_names(self) -> tuple[str, ...]:
        """Names accepted by the light-intensity setters (``"ambient"`` is the headlight)."""
        return (*(spec.name for spec in self.lights), "ambient")


# -- the belt's state -----------------------------------------------------------------------
@dataclass
class BeltItem:
    """An object riding the belt."""

    id: int
    name: str
    s_m: float
    lateral_m: float
    yaw_rad: float


@dataclass(frozen=True)
class ConveyorState:
    """What the API reports about the belt."""

    running: bool
    speed_m_s: float
    mode: str
    dwell_s: float | None
    at_station: bool
    travel_m: float
    halted: bool = False
    """True while the cell's emergency stop holds the belt (it resumes on reset)."""

    def as_dict(self) -> dict[str, object]:
        """JSON-friendly form."""
        return {
            "running": self.running,
            "speed_m_s": self.speed_m_s,
            "mode": self.mode,
            "dwell_s": self.dwell_s,
            "at_station": self.at_station,
            "travel_m": self.travel_m,
            "halted": self.halted,
        }


class Conveyor:
    """Belt kinematics: items move at the set speed; indexing stops them at the station.

    Parameters
    ----------
    spec : ConveyorSpec
        Geometry.
    speed_m_s : float
        Belt speed when running (>= 0).
    mode : {"continuous", "index"}
        Continuous, or stop-and-go: the belt stops when the next upstream item reaches the
        station, waits ``dwell_s`` (or until :meth:`release` when ``dwell_s`` is None), and
        goes on.
    at_end : {"recycle", "remove"}
        What happens to items that run off the end: back to the entry, or gone.
    """

    def __init__(
        self,
        spec: ConveyorSpec,
        *,
        speed_m_s: float = 0.1,
        mode: str = "continuous",
        running: bool = False,
        dwell_s: float | None = 3.0,
        at_end: str = "recycle",
    ) -> None:
        if at_end not in ("recycle", "remove"):
            raise ValueError(f"at_end must be 'recycle' or 'remove', got {at_end!r}")
        self.spec = spec
        self.at_end = at_end
        self.items: dict[int, BeltItem] = {}
        self.travel_m = 0.0
        self._dwell_left = 0.0
        self._holding = False
        #: Items at the station that were held and released (index mode): they go on.  An
        #: item lying at the station that was never held (placed there) is held first.
        self._released: set[int] = set()
        self.running = False
        self.speed_m_s = 0.0
        self.mode = "continuous"
        self.dwell_s: float | None = None
        self.halted = False
        self.configure(running=running, speed_m_s=speed_m_s, mode=mode, dwell_s=dwell_s)

    def configure(
        self,
        *,
        running: bool | None = None,
        speed_m_s: float | None = None,
        mode: str | None = None,
        dwell_s: float | str | None = "keep",
    ) -> ConveyorState:
        """Change any of running, speed, mode and dwell (``"keep"`` leaves dwell unchanged).

        Starting the belt while it is halted (:meth:`halt`) raises :class:`~robot.errors.SimError`.
        Every value is checked before anything changes (:class:`~vision.errors.InvalidInput`,
        a ``ValueError``, quoting the bad one).
        """
        if running is not None and not isinstance(running, bool | np.bool_):
            raise InvalidInput(f"running must be true or false, got {running!r}")
        if speed_m_s is not None and (isinstance(speed_m_s, bool) or not (0.0 <= speed_m_s <= 2.0)):
            raise InvalidInput(f"speed_m_s must be in [0, 2] m/s, got {speed_m_s!r}")
        if running and self.halted:
            from robot.errors import SimError

            raise SimError("the conveyor is halted by the emergency stop: reset the cell first")
        if mode is not None and mode not in CONVEYOR_MODES:
            raise InvalidInput(f"mode must be one of {CONVEYOR_MODES}, got {mode!r}")
        if (
            dwell_s != "keep"
            and dwell_s is not None
            and (
                isinstance(dwell_s, bool)
                or not isinstance(dwell_s, int | float)
                or not 0.0 <= float(dwell_s) <= 3600.0
            )
        ):
            raise InvalidInput(f"dwell_s must be in [0, 3600] s or None, got {dwell_s!r}")
        if speed_m_s is not None:
            self.speed_m_s = float(speed_m_s)
        if mode is not None and mode != self.mode:
            self.mode = mode
            self._holding = False
            self._dwell_left = 0.0
        if dwell_s != "keep":
            self.dwell_s = None if dwell_s is None else float(dwell_s)
        if running is not None:
            self.running = bool(running)
        return self.state

    @property
    def state(self) -> ConveyorState:
        """The belt's current settings and whether it holds an item at the station."""
        return ConveyorState(
            self.running and not self.halted,
            self.speed_m_s,
            self.mode,
            self.dwell_s,
            self._holding,
            self.travel_m,
            self.halted,
        )

    def halt(self) -> None:
        """Emergency stop: the belt stands still at once and until :meth:`resume`; whether it
        was running is kept."""
        self.halted = True

    def resume(self) -> None:
        """After an emergency stop is reset: the belt runs again if it was running."""
        self.halted = False

    def release(self) -> None:
        """Index mode: let the item waiting at the station go on now."""
        self._holding = False
        self._dwell_left = 0.0
        self._released.update(self._at_station())

    def _at_station(self) -> list[int]:
        st = self.spec.station_s_m
        return [i for i, it in self.items.items() if abs(st - it.s_m) <= 1e-9]

    def _next_gap(self) -> float | None:
        """Belt travel until the next item to hold reaches the station: one upstream of it,
        or one lying at it that was never held (0)."""
        st = self.spec.station_s_m
        gaps = [st - it.s_m for i, it in self.items.items()
                if st - it.s_m > 1e-9 or (abs(st - it.s_m) <= 1e-9 and i not in self._released)]  # fmt: skip
        return min(gaps) if gaps else None

    def _move(self, ds: float) -> None:
        self.travel_m += ds
        for it in self.items.values():
            it.s_m += ds
        if ds > 1e-9:  # a released item has left the station (it is held again next time)
            self._released.intersection_update(self._at_station())

    def advance(self, dt_s: float) -> list[int]:
        """Run the belt for ``dt_s`` seconds; returns the ids of items removed at the end."""
        remaining = float(dt_s)
        while self.running and not self.halted and remaining > 1e-12 and self.speed_m_s > 0.0:
            if self.mode == "index" and self._holding:
                if self.dwell_s is None:
                    break
                used = min(remaining, self._dwell_left)
                self._dwell_left -= used
                remaining -= used
                if self._dwell_left <= 1e-12:
                    self._holding = False
                    self._released.update(self._at_station())
                continue
            ds = self.speed_m_s * remaining
            if self.mode == "index":
                gap = self._next_gap()
                if gap is not None and gap <= ds:
                    self._move(gap)
                    remaining -= gap / self.speed_m_s
                    self._holding = True
                    self._dwell_left = self.dwell_s or 0.0
                    continue
            self._move(ds)
            remaining = 0.0
        removed = []
        length = self.spec.length_m
        for it in list(self.items.values()):
            if it.s_m > length:
                if self.at_end == "recycle":
                    it.s_m -= length
                else:
                    removed.append(it.id)
                    del self.items[it.id]
        return removed


# -- static geometry ------------------------------------------------------------------------
def add_world(b: MjcfBuilder, layout: WorldLayout) -> list[str]:
    """Floor, table, conveyor frame, belt, station marks, lights and the belt's stripe bodies.

    Returns the names of the stripe (cleat) mocap bodies, upstream first.
    """
    wb = b.worldbody
    b.texture("floor", tx.floor_image())
    b.material("floor", texture="floor", texrepeat=(6, 6), texuniform=True, specular=0.05)
    b.visual_geom(wb, name="floor", type="plane", size="4 4 0.05", material="floor")
    # Yellow safety line round the arm.
    b.material("safety", rgba=(0.9, 0.75, 0.1, 1), specular=0.1)
    for i in range(24):
        a = 2 * math.pi * i / 24
        b.visual_geom(
            wb,
            type="box",
            size="0.07 0.012 0.0008",
            material="safety",
            pos=fmt((0.5 * math.cos(a), 0.5 * math.sin(a), 0.0008)),
            euler=fmt((0, 0, a + math.pi / 2)),
        )
    # Table.
    tx_, ty_ = layout.table_centre_xy
    sx, sy = layout.table_size_xy
    top = layout.table_top_z_m
    b.material("wood", rgba=(0.62, 0.5, 0.36, 1), specular=0.1)
    b.material("steel", rgba=(0.55, 0.57, 0.6, 1), specular=0.5, shininess=0.5)
    b.material("darksteel", rgba=(0.25, 0.26, 0.28, 1), specular=0.4, shininess=0.4)
    b.visual_geom(
        wb,
        name="table",
        type="box",
        size=fmt((sx / 2, sy / 2, 0.015)),
        pos=fmt((tx_, ty_, top - 0.015)),
        material="wood",
    )
    for dx in (-1, 1):
        for dy in (-1, 1):
            b.visual_geom(
                wb,
                type="box",
                size=fmt((0.02, 0.02, (top - 0.03) / 2)),
                material="steel",
                pos=fmt((tx_ + dx * (sx / 2 - 0.04), ty_ + dy * (sy / 2 - 0.04), (top - 0.03) / 2)),
            )
    # Conveyor: belt, side rails, end rollers, legs.
    c = layout.conveyor
    x0, y0, y1, z = c.centre_x_m, c.start_y_m, c.end_y_m, c.surface_z_m
    ym, L, w = (y0 + y1) / 2, c.length_m, c.width_m
    b.material("belt", rgba=(0.16, 0.17, 0.18, 1), specular=0.05, shininess=0.1)
    b.material("rail", rgba=(0.7, 0.72, 0.75, 1), specular=0.6, shininess=0.5)
    b.visual_geom(
        wb,
        name="belt",
        type="box",
        size=fmt((w / 2, L / 2, 0.02)),
        pos=fmt((x0, ym, z - 0.02)),
        material="belt",
    )
    for side in (-1, 1):
        b.visual_geom(
            wb,
            type="box",
            size=fmt((0.02, L / 2 + 0.05, 0.045)),
            material="rail",
            pos=fmt((x0 + side * (w / 2 + 0.02), ym, z - 0.015)),
        )
        for y in np.linspace(y0 + 0.1, y1 - 0.1, 4):
            b.visual_geom(
                wb,
                type="box",
                size=fmt((0.025, 0.025, (z - 0.06) / 2)),
                material="darksteel",
                pos=fmt((x0 + side * (w / 2 + 0.02), y, (z - 0.06) / 2)),
            )
    for y in (y0, y1):
        b.visual_geom(
            wb,
            type="cylinder",
            size=fmt((0.04, w / 2)),
            material="rail",
            pos=fmt((x0, y, z - 0.04)),
            euler=fmt((0, math.pi / 2, 0)),
        )
    # Station: yellow marks on both rails and a photo-eye pair.
    b.material("mark", rgba=(0.95, 0.8, 0.1, 1), specular=0.1)
    b.material("sensor", rgba=(0.1, 0.1, 0.12, 1), specular=0.3)
    b.material("lens", rgba=(0.9, 0.1, 0.1, 1), specular=0.8, shininess=0.8)
    for side in (-1, 1):
        xr = x0 + side * (w / 2 + 0.02)
        b.visual_geom(
            wb,
            type="box",
            size="0.021 0.01 0.0015",
            material="mark",
            pos=fmt((xr, c.station_y_m, z + 0.031)),
        )
        b.visual_geom(
            wb,
            type="box",
            size="0.015 0.015 0.03",
            material="sensor",
            pos=fmt((xr, c.station_y_m - 0.2, z + 0.06)),
        )
        b.visual_geom(
            wb,
            type="cylinder",
            size="0.006 0.002",
            material="lens",
            pos=fmt((xr - side * 0.016, c.station_y_m - 0.2, z + 0.07)),
            euler=fmt((0, math.pi / 2, 0)),
        )
    # Painted stripes on the belt that move with it (mocap bodies).
    b.material("stripe", rgba=(0.42, 0.43, 0.45, 1), specular=0.05)
    names = []
    n = math.ceil(L / c.cleat_spacing_m)
    for i in range(n):
        name = f"cleat{i}"
        body = ET.SubElement(wb, "body", name=name, mocap="true", pos=fmt((x0, y0 + i * L / n, z)))
        b.visual_geom(body, type="box", size=fmt((w / 2 - 0.01, 0.008, 0.0006)), material="stripe")
        names.append(name)
    # Lights.
    for spec in layout.lights:
        attrs = {
            "name": spec.name,
            "pos": fmt(spec.pos),
            "dir": fmt(spec.dir),
            "diffuse": fmt([spec.diffuse] * 3),
            "specular": fmt([0.3 * spec.diffuse] * 3),
            "castshadow": "true" if spec.castshadow else "false",
            "directional": "true" if spec.kind == "directional" else "false",
        }
        if spec.kind == "spot":
            attrs["cutoff"] = f"{spec.cutoff_deg:g}"
            attrs["exponent"] = "2"
        ET.SubElement(wb, "light", attrs)
    add_bins(b, layout.bins)
    return names


def cleat_positions(spec: ConveyorSpec, travel_m: float, count: int) -> NDArray[np.float64]:
    """Positions of the belt's ``count`` evenly spaced stripes after it has moved ``travel_m``,
    shape (count, 3)."""
    s = (np.arange(count) * (spec.length_m / count) + travel_m) % spec.length_m
    return np.stack(
        [
            np.full(count, spec.centre_x_m),
            spec.start_y_m + s,
            np.full(count, spec.surface_z_m + 0.0006),
        ],
        axis=1,
    )
