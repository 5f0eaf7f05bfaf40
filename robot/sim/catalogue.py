"""The catalogue of objects that ride the conveyor: car wheels, parts, and unknown parts.

Everything is generated in code: meshes from :mod:`robot.sim.meshes`, textures from
:mod:`robot.sim.textures`.  Each entry's object frame has its origin at the centre of the
object's footprint on the belt surface, z up; ``T_base_obj`` of an object on the belt is
therefore the belt point under it with a rotation about z.

The catalogue holds (section 4.1 of the chapter: car wheels on an assembly line):

* six car-wheel types whose rims differ in spoke count and shape, bolt count, width and tyre
  lettering; ``wheel-5spoke`` and ``wheel-5spoke-redband`` are identical seen from the top
  and differ only on the tread (a red band and lettering), i.e. only from the side;
* five other parts with distinctive side features (a shaft boss, ports, a nozzle, cable
  glands, a bracket's upright plate); the bracket has two sitting bases, catalogued as
  ``bracket-upright`` and ``bracket-flat`` (the chapter treats an object on another base as
  a separate object);
* two parts flagged ``trainable=False`` (a brake disc and an oil filter) that recognition
  must reject as unknown.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from robot.sim import textures as tx
from robot.sim.meshes import Mesh, box, concat, disc, revolve, transformed

__all__ = ["CATALOGUE", "CatalogueEntry", "Material", "ObjectGeometry", "Piece", "catalogue_names"]

RGBA = tuple[float, float, float, float]


@dataclass(frozen=True)
class Material:
    """Surface of a piece: a texture image (or None) tinted by ``rgba``."""

    texture: NDArray[np.uint8] | None = None
    rgba: RGBA = (1.0, 1.0, 1.0, 1.0)
    specular: float = 0.3
    shininess: float = 0.3


@dataclass(frozen=True)
class Piece:
    """One mesh of an object, in the object frame, with the key of its material."""

    mesh: Mesh
    material: str


@dataclass(frozen=True)
class ObjectGeometry:
    """Meshes and materials of one catalogue entry (object frame, metres)."""

    pieces: tuple[Piece, ...]
    materials: dict[str, Material]

    @property
    def bounds(self) -> NDArray[np.float64]:
        """``[[xmin, ymin, zmin], [xmax, ymax, zmax]]`` over all pieces."""
        b = np.stack([p.mesh.bounds for p in self.pieces])
        return np.stack([b[:, 0].min(axis=0), b[:, 1].max(axis=0)])

    def color_of(self, piece: Piece) -> tuple[int, int, int]:
        """Mean colour of a piece's material (for simple drawings such as the 3D view)."""
        mat = self.materials[piece.material]
        rgb = np.array(mat.rgba[:3])
        if mat.texture is not None:
            rgb = rgb * mat.texture.reshape(-1, 3).mean(axis=0) / 255.0
        return tuple(round(255 * float(c)) for c in np.clip(rgb, 0, 1))  # type: ignore[return-value]


@dataclass(frozen=True)
class CatalogueEntry:
    """A kind of object that can be spawned on the belt.

    Attributes
    ----------
    name : str
        Catalogue name (the API's ``name``).
    kind : str
        ``"wheel"`` or ``"part"``.
    trainable : bool
        False for parts that are never trained (recognition must reject them).
    description : str
        One line for people.
    base_of : str
        Name of the physical part (entries sharing it are sitting bases of one part).
    build : callable
        Returns the :class:`ObjectGeometry` (cached).
    """

    name: str
    kind: str
    trainable: bool
    description: str
    base_of: str
    build: Callable[[], ObjectGeometry] = field(repr=False, compare=False)

    def geometry(self) -> ObjectGeometry:
        """The entry's meshes and materials (built once)."""
        return _cached_geometry(self.name)

    def summary(self) -> dict[str, object]:
        """JSON-friendly facts (name, kind, trainable, size)."""
        b = self.geometry().bounds
        return {
            "name": self.name,
            "kind": self.kind,
            "trainable": self.trainable,
            "description": self.description,
            "part": self.base_of,
            "size_m": [round(float(v), 4) for v in b[1] - b[0]],
            "height_m": round(float(b[1, 2]), 4),
        }


# -- building blocks ------------------------------------------------------------------------
def _Rx(a: float) -> NDArray[np.float64]:
    c, s = math.cos(a), math.sin(a)
    T = np.eye(4)
    T[1:3, 1:3] = [[c, -s], [s, c]]
    return T


def _Ry(a: float) -> NDArray[np.float64]:
    c, s = math.cos(a), math.sin(a)
    T = np.eye(4)
    T[0, 0], T[0, 2], T[2, 0], T[2, 2] = c, s, -s, c
    return T


def _at(x: float, y: float, z: float) -> NDArray[np.float64]:
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


def _cylinder(radius: float, z0: float, z1: float, *, segments: int = 40) -> Mesh:
    """Closed cylinder about z from z0 to z1 (profile walked with the outside on the left)."""
    return revolve([(0.0, z1), (radius, z1), (radius, z0), (0.0, z0)], segments=segments)


def _tube(r_out: float, r_in: float, z0: float, z1: float, *, segments: int = 40) -> Mesh:
    """Closed thick-walled tube about z."""
    return revolve(
        [(r_in, z1), (r_out, z1), (r_out, z0), (r_in, z0), (r_in, z1)], segments=segments
    )


def _along_x(mesh: Mesh, x: float, y: float, z: float) -> Mesh:
    """A mesh built along +z, turned to point along +x and placed at (x, y, z)."""
    return transformed(mesh, _at(x, y, z) @ _Ry(math.pi / 2))


def _along_y(mesh: Mesh, x: float, y: float, z: float, sign: float = 1.0) -> Mesh:
    """A mesh built along +z, turned to point along ``sign`` * y and placed at (x, y, z)."""
    return transformed(mesh, _at(x, y, z) @ _Rx(-sign * math.pi / 2))


def _solid(rgb: tuple[int, int, int], specular: float = 0.3, shininess: float = 0.3) -> Material:
    return Material(None, (rgb[0] / 255, rgb[1] / 255, rgb[2] / 255, 1.0), specular, shininess)


# -- wheels ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class WheelDesign:
    """Parameters of a car wheel lying flat on the belt (axis vertical)."""

    radius_m: float
    rim_radius_m: float
    width_m: float
    spokes: int
    style: str
    bolts: int
    rim_rgb: tuple[int, int, int]
    sidewall_text: str
    cap_text: str = ""
    tread_text: str = ""
    band_rgb: tuple[int, int, int] | None = None
    tread_style: str = "blocks"
    seed: int = 0


# v ranges of the tyre texture: upper sidewall, shoulders, lower sidewall and bead.
_BANDS = ((0.0, 0.4), (0.45, 0.7), (0.75, 0.95))


def build_wheel(d: WheelDesign) -> ObjectGeometry:
    """Tyre (surfaces of revolution with sidewall and tread textures), rim barrel and face."""
    R, r, W = d.radius_m, d.rim_radius_m, d.width_m
    rho = 0.28 * W  # shoulder radius
    bead = 0.012
    arc = np.linspace(0.0, math.pi / 2, 6)
    shoulder_top = [(R - rho + rho * math.sin(a), W - rho + rho * math.cos(a)) for a in arc]
    shoulder_bottom = [(R - rho + rho * math.cos(a), rho - rho * math.sin(a)) for a in arc]
    top = [(r, W - bead), (r + 0.35 * (R - rho - r), W - 0.002), (R - rho, W)]
    bottom = [(R - rho, 0.0), (r + 0.35 * (R - rho - r), 0.002), (r, bead)]
    seg = 72
    h0, h1 = _BANDS[1]
    tyre = concat(
        [
            revolve(top, segments=seg, v_range=_BANDS[0]),
            revolve(shoulder_top, segments=seg, v_range=(h0, (h0 + h1) / 2)),
            revolve(shoulder_bottom, segments=seg, v_range=((h0 + h1) / 2, h1)),
            revolve(bottom, segments=seg, v_range=_BANDS[2]),
            revolve([(r, bead), (r, W - bead)], segments=seg, v_range=(0.97, 1.0)),
        ]
    )
    tread = revolve([(R, W - rho), (R, rho)], segments=seg, v_range=(0.0, 1.0))
    face_z = W - 0.03
    barrel = revolve(
        [(r * 0.998, face_z), (r * 0.998, W - 0.006), (r + 0.007, W - 0.001)], segments=seg
    )
    face = disc(r * 0.998, face_z, segments=seg)
    tyre_tex = tx.tyre_image(
        sidewall_text=d.sidewall_text, bands=_BANDS, tread_style=d.tread_style, seed=d.seed
    )
    tread_tex = tx.tread_image(
        tread_text=d.tread_text, band_rgb=d.band_rgb, tread_style=d.tread_style, seed=d.seed
    )
    rim_tex = tx.rim_face_image(
        spokes=d.spokes,
        style=d.style,
        bolts=d.bolts,
        rim_rgb=d.rim_rgb,
        cap_text=d.cap_text,
        seed=d.seed,
    )
    return ObjectGeometry(
        pieces=(
            Piece(tyre, "tyre"),
            Piece(tread, "tread"),
            Piece(barrel, "barrel"),
            Piece(face, "rim"),
        ),
        materials={
            "tyre": Material(tyre_tex, specular=0.08, shininess=0.1),
            "tread": Material(tread_tex, specular=0.08, shininess=0.1),
            "barrel": _solid(d.rim_rgb, 0.6, 0.6),
            "rim": Material(rim_tex, specular=0.5, shininess=0.5),
        },
    )


WHEELS: dict[str, tuple[str, WheelDesign]] = {
    "wheel-5spoke": (
        "5 straight spokes, 4 bolts, 95 mm wide, plain tread",
        WheelDesign(
            0.165,
            0.112,
            0.095,
            5,
            "straight",
            4,
            (190, 192, 198),
            "VISIONCELL TOURING 195/65 R15",
            "VC",
            seed=1,
        ),
    ),
    "wheel-5spoke-redband": (
        "same rim and sidewall as wheel-5spoke (identical from the top); red band and SPORT lettering on the tread",
        WheelDesign(
            0.165,
            0.112,
            0.095,
            5,
            "straight",
            4,
            (190, 192, 198),
            "VISIONCELL TOURING 195/65 R15",
            "VC",
            tread_text="SPORT",
            band_rgb=(200, 25, 30),
            seed=1,
        ),
    ),
    "wheel-7spoke-curved": (
        "7 curved spokes, 5 bolts, 85 mm wide, anthracite",
        WheelDesign(
            0.17,
            0.122,
            0.085,
            7,
            "curved",
            5,
            (80, 84, 92),
            "ECO CONTACT 205/55 R16",
            "E",
            tread_style="ribs",
            seed=2,
        ),
    ),
    "wheel-10spoke-twin": (
        "5 pairs of thin spokes, 5 bolts, 110 mm wide",
        WheelDesign(
            0.172,
            0.128,
            0.11,
            5,
            "twin",
            5,
            (215, 216, 220),
            "SPORT CONTACT 225/45 R17",
            "S",
            seed=3,
        ),
    ),
    "wheel-steel": (
        "black steel rim with 8 round holes, 4 bolts, 80 mm wide",
        WheelDesign(
            0.16, 0.105, 0.08, 8, "holes", 4, (40, 40, 44), "WINTER M+S 185/65 R15", seed=4
        ),
    ),
    "wheel-6spoke-split": (
        "6 Y-split spokes, 6 bolts, 120 mm wide, gold",
        WheelDesign(
            0.175, 0.13, 0.12, 6, "split", 6, (200, 160, 70), "ALL TERRAIN 235/60 R18", "AT", seed=5
        ),
    ),
}


# -- parts ----------------------------------------------------------------------------------
def build_gear_housing() -> ObjectGeometry:
    """Blue box with a screwed lid; a shaft boss on +x and a red oil plug on -y."""
    at = tx.Atlas(2)
    side = at.add(tx.metal_tile((45, 85, 150), seed=11, brushed=False))
    label = at.add(
        tx.label_tile("GH-200", bg=(45, 85, 150), fg=(20, 20, 20), plate=(220, 220, 215), seed=12)
    )
    lid = at.add(tx.metal_tile((55, 95, 160), seed=13, brushed=False, screws=4))
    sx, sy, sz = 0.18, 0.13, 0.10
    body = box((sx, sy, sz), [side, side, label, side, lid, side], center=(0, 0, sz / 2))
    boss = _along_x(_cylinder(0.032, 0.0, 0.04), sx / 2, 0.0, 0.05)
    shaft = _along_x(_cylinder(0.012, 0.04, 0.075), sx / 2, 0.0, 0.05)
    plug = _along_y(_cylinder(0.014, 0.0, 0.012), 0.03, -sy / 2, 0.03, sign=-1.0)
    return ObjectGeometry(
        (Piece(body, "body"), Piece(boss, "boss"), Piece(shaft, "steel"), Piece(plug, "plug")),
        {
            "body": Material(at.image, specular=0.3),
            "boss": _solid((45, 85, 150)),
            "steel": _solid((200, 200, 205), 0.8, 0.7),
            "plug": _solid((200, 30, 30)),
        },
    )


def build_valve_block() -> ObjectGeometry:
    """Red anodised block, three ports on the +x face, a black solenoid on top."""
    at = tx.Atlas(2)
    side = at.add(tx.metal_tile((170, 40, 35), seed=21))
    plate = at.add(
        tx.label_tile("VB-3", bg=(170, 40, 35), fg=(15, 15, 15), plate=(230, 230, 230), seed=22)
    )
    top = at.add(tx.metal_tile((180, 45, 40), seed=23, screws=4))
    sx, sy, sz = 0.15, 0.11, 0.10
    body = box((sx, sy, sz), [side, side, plate, side, top, side], center=(0, 0, sz / 2))
    pieces = [Piece(body, "body")]
    for y in (-0.035, 0.0, 0.035):
        pieces.append(Piece(_along_x(_tube(0.013, 0.007, 0.0, 0.018), sx / 2, y, 0.05), "brass"))
    pieces.append(Piece(_cylinder(0.026, sz, sz + 0.05), "coil"))
    pieces.append(Piece(_cylinder(0.008, sz + 0.05, sz + 0.062), "brass"))
    return ObjectGeometry(
        tuple(pieces),
        {
            "body": Material(at.image),
            "brass": _solid((190, 150, 60), 0.7, 0.6),
            "coil": _solid((25, 25, 28), 0.4, 0.5),
        },
    )


def build_pipe_flange() -> ObjectGeometry:
    """Steel tube standing on a flange, with a flanged side nozzle on +x."""
    pieces = [
        Piece(_tube(0.085, 0.045, 0.0, 0.016), "steel"),
        Piece(_tube(0.048, 0.04, 0.016, 0.17), "steel"),
        Piece(_along_x(_tube(0.022, 0.015, 0.0, 0.055), 0.045, 0.0, 0.1), "steel"),
        Piece(_along_x(_tube(0.036, 0.015, 0.055, 0.065), 0.045, 0.0, 0.1), "paint"),
    ]
    for i in range(6):  # flange bolts
        a = 2 * math.pi * i / 6
        bolt = _cylinder(0.007, 0.016, 0.026, segments=12)
        pieces.append(
            Piece(transformed(bolt, _at(0.066 * math.cos(a), 0.066 * math.sin(a), 0.0)), "bolt")
        )
    return ObjectGeometry(
        tuple(pieces),
        {
            "steel": _solid((160, 165, 170), 0.7, 0.5),
            "paint": _solid((30, 110, 60)),
            "bolt": _solid((60, 60, 62)),
        },
    )


def build_junction_box() -> ObjectGeometry:
    """Grey box, hazard-striped warning face on -x, cable glands on +x (two) and -y (one)."""
    at = tx.Atlas(2)
    grey = at.add(tx.metal_tile((175, 178, 180), seed=31, brushed=False))
    warn = at.add(
        tx.label_tile(
            "400 V",
            bg=(175, 178, 180),
            fg=(20, 20, 20),
            plate=(240, 200, 30),
            stripes=True,
            seed=32,
        )
    )
    lid = at.add(tx.label_tile("JB-16", bg=(165, 168, 170), fg=(30, 30, 30), seed=33))
    s = 0.16
    h = 0.08
    body = box((s, s, h), [grey, warn, grey, grey, lid, grey], center=(0, 0, h / 2))
    pieces = [Piece(body, "body")]
    for y in (-0.04, 0.04):
        pieces.append(Piece(_along_x(_cylinder(0.013, 0.0, 0.025), s / 2, y, 0.04), "gland"))
    pieces.append(
        Piece(_along_y(_cylinder(0.016, 0.0, 0.03), 0.0, -s / 2, 0.04, sign=-1.0), "gland")
    )
    return ObjectGeometry(
        tuple(pieces), {"body": Material(at.image), "gland": _solid((20, 20, 22), 0.3, 0.4)}
    )


def build_bracket(*, flat: bool) -> ObjectGeometry:
    """Zinc-plated L bracket: base plate, upright plate with two holes, a gusset.

    Upright: sits on its base plate.  Flat: the same part lying on the back of its upright
    plate (the base plate then stands up), its second sitting base.
    """
    at = tx.Atlas(2)
    plate = at.add(tx.label_tile("", bg=(185, 180, 150), fg=(0, 0, 0), holes=2, seed=41))
    plain = at.add(tx.metal_tile((185, 180, 150), seed=42))
    stamp = at.add(tx.label_tile("LB-160", bg=(185, 180, 150), fg=(40, 40, 40), seed=43))
    t = 0.012
    base = box(
        (0.16, 0.10, t), [plain, plain, stamp, plain, plate, plain], center=(0.0, 0.0, t / 2)
    )
    upright = box(
        (t, 0.10, 0.13),
        [plate, plain, plain, plain, plain, plain],
        center=(-0.08 + t / 2, 0.0, 0.065),
    )
    gusset = transformed(
        box((0.05, 0.008, 0.05), [plain] * 6, center=(0.0, 0.0, 0.0)),
        _at(-0.08 + t + 0.025, 0.0, t + 0.025) @ _Ry(math.pi / 4),
    )
    mesh = concat([base, upright, gusset])
    if flat:
        # Lie on the outer face of the upright plate (x = -0.08): turn about y by +90 deg
        # so that -x becomes -z, then put the lowest point on the belt and centre it.
        m = transformed(mesh, _Ry(-math.pi / 2))
        b = m.bounds
        m = transformed(m, _at(-(b[0, 0] + b[1, 0]) / 2, -(b[0, 1] + b[1, 1]) / 2, -b[0, 2]))
        mesh = m
    return ObjectGeometry(
        (Piece(mesh, "zinc"),), {"zinc": Material(at.image, specular=0.6, shininess=0.5)}
    )


def build_brake_disc() -> ObjectGeometry:
    """Brake disc with a raised hat (never trained)."""
    import cv2

    S = 256
    img = np.full((S, S, 3), 150, np.uint8)
    cv2.circle(img, (S // 2, S // 2), int(S * 0.48), (120, 118, 115), 3, cv2.LINE_AA)
    for i in range(24):
        a = 2 * math.pi * i / 24
        for rr in (0.36, 0.42):
            p = (int(S / 2 + rr * S * math.cos(a + rr)), int(S / 2 - rr * S * math.sin(a + rr)))
            cv2.circle(img, p, 4, (30, 30, 30), -1, cv2.LINE_AA)
    pieces = (
        Piece(_tube(0.14, 0.07, 0.0, 0.026), "iron"),
        Piece(disc(0.1399, 0.0262, segments=64), "face"),
        Piece(_tube(0.082, 0.03, 0.0, 0.055), "hat"),
    )
    return ObjectGeometry(
        pieces,
        {
            "iron": _solid((120, 118, 115), 0.5, 0.4),
            "face": Material(img, specular=0.6),
            "hat": _solid((70, 70, 72)),
        },
    )


def build_oil_filter() -> ObjectGeometry:
    """Blue canister with a wrapped label (never trained)."""
    tex = tx.label_tile(
        "OIL FILTER", bg=(30, 70, 170), fg=(250, 250, 250), plate=(30, 70, 170), seed=51
    )
    tex = np.concatenate([tex, tex, tex], axis=1)
    pieces = (
        Piece(revolve([(0.05, 0.12), (0.05, 0.005)], segments=48, v_range=(1.0, 0.0)), "label"),
        Piece(_tube(0.05, 0.018, 0.12, 0.128), "lid"),
        Piece(_cylinder(0.05, 0.0, 0.005), "lid"),
    )
    return ObjectGeometry(
        pieces, {"label": Material(tex), "lid": _solid((150, 150, 155), 0.6, 0.5)}
    )


# -- the catalogue --------------------------------------------------------------------------
def _entries() -> dict[str, CatalogueEntry]:
    out: dict[str, CatalogueEntry] = {}
    for name, (desc, design) in WHEELS.items():
        out[name] = CatalogueEntry(
            name, "wheel", True, desc, name, functools.partial(build_wheel, design)
        )
    parts: list[tuple[str, bool, str, str, Callable[[], ObjectGeometry]]] = [
        (
            "gear-housing",
            True,
            "blue gearbox housing; shaft boss on one side, oil plug on another",
            "gear-housing",
            build_gear_housing,
        ),
        (
            "valve-block",
            True,
            "red valve block; three brass ports on one side, solenoid on top",
            "valve-block",
            build_valve_block,
        ),
        (
            "pipe-flange",
            True,
            "flanged steel pipe with a side nozzle",
            "pipe-flange",
            build_pipe_flange,
        ),
        (
            "junction-box",
            True,
            "grey junction box; warning plate and cable glands on the sides",
            "junction-box",
            build_junction_box,
        ),
        (
            "bracket-upright",
            True,
            "L bracket standing on its base plate",
            "bracket",
            functools.partial(build_bracket, flat=False),
        ),
        (
            "bracket-flat",
            True,
            "the same L bracket lying on its upright plate",
            "bracket",
            functools.partial(build_bracket, flat=True),
        ),
        (
            "brake-disc",
            False,
            "brake disc (never trained: for rejection tests)",
            "brake-disc",
            build_brake_disc,
        ),
        (
            "oil-filter",
            False,
            "oil filter (never trained: for rejection tests)",
            "oil-filter",
            build_oil_filter,
        ),
    ]
    for name, trainable, desc, part, build in parts:
        out[name] = CatalogueEntry(name, "part", trainable, desc, part, build)
    return out


CATALOGUE: dict[str, CatalogueEntry] = _entries()


@functools.cache
def _cached_geometry(name: str) -> ObjectGeometry:
    return CATALOGUE[name].build()


def catalogue_names() -> list[str]:
    """Every catalogue name, in catalogue order."""
    return list(CATALOGUE)
