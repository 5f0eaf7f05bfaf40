"""What an object model may hold (:mod:`backend.recognition.models`): the checks of its
names, threshold, kind and geometry (height, grasp point), and the validated fields of a
create or an update (:class:`ModelFields`)."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from backend.db.models import ObjectKind, ObjectModel
from vision.errors import InvalidInput

#: Names of models, parts and bases: letters, digits and ``_ . -``, starting with a letter
#: or digit, at most 64 characters (the database column).
NAME_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.\-]{0,63}$")

#: Tallest object and farthest grasp point from the footprint centre a model may give, m.
MAX_HEIGHT_M = 0.5
MAX_GRASP_OFFSET_M = 0.5


def check_name(value: object, what: str) -> str:
    """Validate a model, part or base name; return it."""
    if not isinstance(value, str) or not NAME_PATTERN.match(value):
        raise InvalidInput(
            f"{what} must be 1-64 letters, digits or '_ . -' starting with a letter or digit, "
            f"got {value!r}"
        )
    return value


def check_threshold(value: object) -> float | None:
    """Validate an optional score threshold in [0, 1]."""
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InvalidInput(f"threshold must be a number in [0, 1] or null, got {value!r}")
    v = float(value)
    if not math.isfinite(v) or not 0.0 <= v <= 1.0:
        raise InvalidInput(f"threshold must be within [0, 1], got {value!r}")
    return v


def parse_kind(value: object) -> ObjectKind:
    """``value`` as an :class:`ObjectKind` (``"2d"`` or ``"3d"``); :class:`InvalidInput` if not."""
    if isinstance(value, ObjectKind):
        return value
    if isinstance(value, str):
        try:
            return ObjectKind(value)
        except ValueError:
            pass
    raise InvalidInput(f"kind must be '2d' or '3d', got {value!r}")


def check_geometry(
    height_m: object, grasp_obj: object
) -> tuple[float | None, tuple[float, float, float] | None]:
    """Validate a model's height (metres, in (0, 0.5]) and grasp point (3 metres, object
    frame, its ``z`` within the height, ``x``/``y`` within 0.5 m); either may be None."""
    h: float | None = None
    if height_m is not None:
        if isinstance(height_m, bool) or not isinstance(height_m, int | float):
            raise InvalidInput(f"height_m must be a number of metres or null, got {height_m!r}")
        h = float(height_m)
        if not (math.isfinite(h) and 0.0 < h <= MAX_HEIGHT_M):
            raise InvalidInput(f"height_m must be in (0, {MAX_HEIGHT_M:g}] m, got {height_m!r}")
    g: tuple[float, float, float] | None = None
    if grasp_obj is not None:
        vals = list(grasp_obj) if isinstance(grasp_obj, list | tuple) else None
        if (
            vals is None
            or len(vals) != 3
            or any(isinstance(v, bool) or not isinstance(v, int | float) for v in vals)
            or not all(math.isfinite(float(v)) for v in vals)
        ):
            raise InvalidInput(
                f"grasp_obj must be 3 finite numbers (metres) or null, got {grasp_obj!r}"
            )
        x, y, z = (float(v) for v in vals)
        if math.hypot(x, y) > MAX_GRASP_OFFSET_M or not 0.0 <= z <= MAX_HEIGHT_M:
            raise InvalidInput(
                f"grasp_obj must lie within {MAX_GRASP_OFFSET_M:g} m of the footprint centre "
                f"and at a height in [0, {MAX_HEIGHT_M:g}] m, got {grasp_obj!r}"
            )
        if h is not None and z > h + 1e-9:
            raise InvalidInput(f"grasp_obj's z ({z:g} m) must not exceed height_m ({h:g} m)")
        g = (x, y, z)
    return h, g


def grasp_of(row: ObjectModel) -> tuple[float, float, float] | None:
    """The stored grasp point of a model (object frame, metres), None if not stored."""
    g = (row.grasp_x_m, row.grasp_y_m, row.grasp_z_m)
    return None if any(v is None for v in g) else (float(g[0]), float(g[1]), float(g[2]))  # type: ignore[arg-type]


@dataclass(frozen=True)
class ModelFields:
    """Validated fields of a model (``None`` = not given, for updates)."""

    name: str | None = None
    part: str | None = None
    sitting_base: str | None = None
    kind: ObjectKind | None = None
    threshold: float | None = None
    description: str | None = None
    threshold_given: bool = False
    """True when ``threshold`` was given (``None`` then clears it)."""
    height_m: float | None = None
    grasp_obj: tuple[float, float, float] | None = None
    height_given: bool = False
    """True when ``height_m`` was given (entered by an engineer; ``None`` clears it)."""
    grasp_given: bool = False
    """True when ``grasp_obj`` was given (entered by an engineer; ``None`` clears it)."""

    def __post_init__(self) -> None:
        h, g = check_geometry(self.height_m, self.grasp_obj)
        object.__setattr__(self, "height_m", h)
        object.__setattr__(self, "grasp_obj", g)
        for what in ("name", "part", "sitting_base"):
            value = getattr(self, what)
            if value is not None:
                check_name(value, what)
        if self.kind is not None and not isinstance(self.kind, ObjectKind):
            object.__setattr__(self, "kind", parse_kind(self.kind))
        object.__setattr__(self, "threshold", check_threshold(self.threshold))
        if self.description is not None and (
            not isinstance(self.description, str) or len(self.description) > 2000
        ):
            raise InvalidInput("description must be text of at most 2000 characters")
