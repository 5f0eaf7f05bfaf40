"""Sorting bins beside the belt: where they stand, what they take, and their drawing.

Each bin is an open box standing on the floor, turned by ``yaw_rad`` about its vertical
axis, with a name, the part names it takes (``CatalogueEntry.base_of``) and a flag for the
reject bin (unknown and failed objects).  The default layout (:func:`default_bins`) puts one
bin per trainable part of the catalogue plus the reject bin round the back of the arm,
where the flange reaches them tool-down (the drop point of every bin is between 0.68 and
1.10 m from the column axis) clear of the conveyor and the calibration table; wheel-sized
bins are 0.40 m square, bins for the smaller parts 0.30 m.

A dropped object lands in the bin whose inner footprint holds its footprint centre (see
:meth:`BinSpec.contains`); :class:`robot.sim.engine.SimEngine` keeps the record.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robot.sim.builder import MjcfBuilder, fmt

__all__ = ["BinSpec", "add_bins", "default_bins"]

_WALL_M = 0.01  # wall and floor thickness


@dataclass(frozen=True)
class BinSpec:
    """One sorting bin.

    Attributes
    ----------
    name : str
        Bin name (a word: letters, digits, ``-`` and ``_``).
    parts : tuple of str
        Part names (``CatalogueEntry.base_of``, the models' ``part``) sorted into it.
    centre_xy : (float, float)
        Centre of the footprint, base frame, metres.
    size_m : float
        Outer side of the square footprint.
    rim_z_m : float
        Height of the rim above the floor.
    yaw_rad : float
        Rotation about the vertical.
    reject : bool
        True for the bin that takes unknown and failed objects.
    """

    name: str
    parts: tuple[str, ...]
    centre_xy: tuple[float, float]
    size_m: float = 0.40
    rim_z_m: float = 0.30
    yaw_rad: float = 0.0
    reject: bool = False

    def __post_init__(self) -> None:
        if not self.name or not all(c.isalnum() or c in "-_" for c in self.name):
            raise ValueError(
                f"bin name must be a word of letters, digits, '-', '_', got {self.name!r}"
            )
        cx, cy = self.centre_xy
        if not (math.isfinite(cx) and math.isfinite(cy) and math.hypot(cx, cy) <= 2.0):
            raise ValueError(
                f"bin {self.name!r}: centre_xy must be finite within 2 m, got {self.centre_xy!r}"
            )
        if not (math.isfinite(self.size_m) and 0.1 <= self.size_m <= 1.0):
            raise ValueError(
                f"bin {self.name!r}: size_m must be in [0.1, 1] m, got {self.size_m!r}"
            )
        if not (math.isfinite(self.rim_z_m) and 0.05 <= self.rim_z_m <= 1.0):
            raise ValueError(
                f"bin {self.name!r}: rim_z_m must be in [0.05, 1] m, got {self.rim_z_m!r}"
            )
        if not math.isfinite(self.yaw_rad):
            raise ValueError(f"bin {self.name!r}: yaw_rad must be finite, got {self.yaw_rad!r}")
        if self.reject and self.parts:
            raise ValueError(
                f"the reject bin {self.name!r} takes no named parts, got {self.parts!r}"
            )
        if not self.reject and not self.parts:
            raise ValueError(f"bin {self.name!r} takes no part: give parts or reject=True")

    @property
    def inner_half_m(self) -> float:
        """Half the inner side (inside the walls)."""
        return self.size_m / 2.0 - _WALL_M

    @property
    def drop_point(self) -> NDArray[np.float64]:
        """Centre of the opening at rim height, base frame."""
        return np.array([self.centre_xy[0], self.centre_xy[1], self.rim_z_m])

    def contains(self, point: ArrayLike) -> bool:
        """Whether ``point`` (x, y[, z]) lies over the bin's inner footprint."""
        p = np.asarray(point, dtype=np.float64).reshape(-1)
        dx, dy = p[0] - self.centre_xy[0], p[1] - self.centre_xy[1]
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        u, v = c * dx + s * dy, -s * dx + c * dy
        h = self.inner_half_m
        return abs(u) <= h and abs(v) <= h

    def corners_xy(self) -> NDArray[np.float64]:
        """Outer footprint corners, (4, 2), base frame."""
        h = self.size_m / 2.0
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        local = np.array([[-h, -h], [h, -h], [h, h], [-h, h]])
        R = np.array([[c, -s], [s, c]])
        return local @ R.T + np.asarray(self.centre_xy)


def default_bins() -> tuple[BinSpec, ...]:
    """One bin per trainable part of the catalogue and a reject bin (see the module doc)."""
    wheels = (
        ("wheel-5spoke", (0.31, 0.61)),
        ("wheel-5spoke-redband", (0.31, 1.02)),
        ("wheel-7spoke-curved", (-0.11, 0.85)),
        ("wheel-10spoke-twin", (-0.53, 0.92)),
        ("wheel-steel", (-0.53, 0.50)),
        ("wheel-6spoke-split", (-0.53, -0.92)),
    )
    parts = (
        ("gear-housing", (-0.90, 0.62)),
        ("valve-block", (-0.90, 0.31)),
        ("pipe-flange", (-0.90, 0.0)),
        ("junction-box", (-0.90, -0.31)),
        ("bracket", (-0.90, -0.62)),
    )
    out = [BinSpec(f"bin-{p}", (p,), xy, 0.40) for p, xy in wheels]
    out += [BinSpec(f"bin-{p}", (p,), xy, 0.30) for p, xy in parts]
    out.append(BinSpec("reject", (), (-0.53, -0.51), 0.40, reject=True))
    return tuple(out)


def check_bins(bins: tuple[BinSpec, ...]) -> None:
    """Distinct names, each part in one bin, at most one reject bin."""
    names = [b.name for b in bins]
    if len(set(names)) != len(names):
        raise ValueError(f"bin names must be distinct, got {names}")
    seen: dict[str, str] = {}
    for b in bins:
        for p in b.parts:
            if p in seen:
                raise ValueError(f"part {p!r} is sorted into two bins: {seen[p]!r} and {b.name!r}")
            seen[p] = b.name
    if sum(b.reject for b in bins) > 1:
        raise ValueError("at most one reject bin")


def add_bins(b: MjcfBuilder, bins: tuple[BinSpec, ...]) -> None:
    """Static bodies of the bins (floor plate and four walls each, visual only)."""
    if not bins:
        return
    b.material("bin", rgba=(0.2, 0.42, 0.7, 1), specular=0.2, shininess=0.2)
    b.material("bin_reject", rgba=(0.75, 0.15, 0.12, 1), specular=0.2, shininess=0.2)
    for spec in bins:
        body = ET.SubElement(
            b.worldbody,
            "body",
            name=f"bin_{spec.name}",
            pos=fmt((spec.centre_xy[0], spec.centre_xy[1], 0.0)),
            euler=fmt((0.0, 0.0, spec.yaw_rad)),
        )
        mat = "bin_reject" if spec.reject else "bin"
        h, t, z = spec.size_m / 2.0, _WALL_M / 2.0, spec.rim_z_m
        b.visual_geom(body, type="box", size=fmt((h, h, t)), pos=fmt((0, 0, t)), material=mat)
        for sx, sy, hx, hy in ((1, 0, t, h), (-1, 0, t, h), (0, 1, h, t), (0, -1, h, t)):
            b.visual_geom(
                body,
                type="box",
                size=fmt((hx, hy, z / 2.0)),
                pos=fmt((sx * (h - t), sy * (h - t), z / 2.0)),
                material=mat,
            )
