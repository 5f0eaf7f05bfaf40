"""A real cell's layout file: the station, the belt and the bins, in TOML or JSON.

The file (``.toml``, or ``.json`` with the same structure) names the station and, when the
cell sorts, its bins; a belt only when there is one through the station::

    [station]
    x_m = 0.8              # base frame, metres
    y_m = 0.0
    surface_z_m = 0.45     # the surface parts lie on

    [belt]                 # optional: a belt along base +y through the station
    start_y_m = -1.3
    end_y_m = 1.3
    width_m = 0.44

    [[bins]]
    name = "bin-wheels"
    parts = ["wheel-5spoke", "wheel-steel"]   # the models' part (else their name)
    drop_m = [0.31, 0.61, 0.30]               # centre of the opening at the rim
    size_m = 0.40                             # optional, drawn in the 3D view
    yaw_deg = 0.0                             # optional, drawn in the 3D view

    [[bins]]
    name = "reject"
    reject = true
    drop_m = [-0.53, -0.51, 0.30]

Every value is checked: an unknown key, a wrong type, a value that is not finite or out
of its range stops the start with a :class:`LayoutError` naming the file, the key and the
value.  Files larger than :data:`MAX_LAYOUT_BYTES` are refused unread.
"""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path
from typing import Any

from robot.cellworld import MAX_BINS, BeltSpan, Bin, CellLayout

__all__ = ["MAX_LAYOUT_BYTES", "LayoutError", "load_layout", "parse_layout"]

#: Largest layout file read, bytes.
MAX_LAYOUT_BYTES = 64 * 1024

_TOP = {"station", "belt", "bins"}
_STATION = {"x_m", "y_m", "surface_z_m"}
_BELT = {"start_y_m", "end_y_m", "width_m"}
_BIN = {"name", "parts", "drop_m", "reject", "size_m", "yaw_deg"}


class LayoutError(ValueError):
    """A layout file that cannot be used; the message names the file, the key and the value."""


def _table(where: str, value: Any, keys: set[str], required: set[str]) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise LayoutError(f"{where} must be a table, got {value!r:.80}")
    unknown = sorted(set(value) - keys)
    if unknown:
        raise LayoutError(f"{where}: unknown key(s) {unknown} (known: {sorted(keys)})")
    missing = sorted(required - set(value))
    if missing:
        raise LayoutError(f"{where}: missing key(s) {missing}")
    return value


def _number(where: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise LayoutError(f"{where} must be a finite number, got {value!r:.80}")
    return float(value)


def _bin(where: str, raw: Any) -> Bin:
    t = _table(where, raw, _BIN, {"name", "drop_m"})
    name = t["name"]
    if not isinstance(name, str):
        raise LayoutError(f"{where}.name must be a string, got {name!r:.80}")
    where = f"{where} ({name!r:.70})"
    drop = t["drop_m"]
    if not isinstance(drop, list) or len(drop) != 3:
        raise LayoutError(f"{where}.drop_m must be [x, y, z] in metres, got {drop!r:.80}")
    xyz = tuple(_number(f"{where}.drop_m[{i}]", v) for i, v in enumerate(drop))
    parts = t.get("parts", [])
    if not isinstance(parts, list) or len(parts) > 256:
        raise LayoutError(f"{where}.parts must be a list of at most 256 names, got {parts!r:.80}")
    for i, p in enumerate(parts):
        if not isinstance(p, str):
            raise LayoutError(f"{where}.parts[{i}] must be a string, got {p!r:.80}")
    reject = t.get("reject", False)
    if not isinstance(reject, bool):
        raise LayoutError(f"{where}.reject must be true or false, got {reject!r:.80}")
    size = _number(f"{where}.size_m", t.get("size_m", 0.4))
    yaw = math.radians(_number(f"{where}.yaw_deg", t.get("yaw_deg", 0.0)))
    try:
        return Bin(name, tuple(parts), (xyz[0], xyz[1], xyz[2]), reject=reject, size_m=size,
                   yaw_rad=yaw)  # fmt: skip
    except ValueError as exc:
        raise LayoutError(f"{where}: {exc}") from None


def parse_layout(data: Any, *, source: str = "layout") -> CellLayout:
    """The :class:`CellLayout` of a decoded layout document (module docstring); a
    :class:`LayoutError` prefixed with ``source`` for anything wrong in it."""
    try:
        top = _table("the layout", data, _TOP, {"station"})
        st = _table("[station]", top["station"], _STATION, _STATION)
        xy = (_number("station.x_m", st["x_m"]), _number("station.y_m", st["y_m"]))
        z = _number("station.surface_z_m", st["surface_z_m"])
        belt = None
        if "belt" in top:
            b = _table("[belt]", top["belt"], _BELT, _BELT)
            vals = [_number(f"belt.{k}", b[k]) for k in ("start_y_m", "end_y_m", "width_m")]
            try:
                belt = BeltSpan(*vals)
            except ValueError as exc:
                raise LayoutError(f"[belt]: {exc}") from None
        raw_bins = top.get("bins", [])
        if not isinstance(raw_bins, list) or len(raw_bins) > MAX_BINS:
            raise LayoutError(f"bins must be a list of at most {MAX_BINS} tables, "
                              f"got {type(raw_bins).__name__} of {len(raw_bins) if isinstance(raw_bins, list) else '?'}")  # fmt: skip
        bins = tuple(_bin(f"bins[{i}]", raw) for i, raw in enumerate(raw_bins))
        try:
            return CellLayout(xy, z, belt, bins, source=source)
        except ValueError as exc:
            raise LayoutError(str(exc)) from None
    except LayoutError as exc:
        raise LayoutError(f"{source}: {exc}") from None


def load_layout(path: str | Path) -> CellLayout:
    """Read, check and return the layout file at ``path`` (``.toml`` or ``.json``)."""
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix not in (".toml", ".json"):
        raise LayoutError(f"layout file {str(p)!r}: must end in .toml or .json")
    try:
        size = p.stat().st_size
        if size > MAX_LAYOUT_BYTES:
            raise LayoutError(f"layout file {str(p)!r}: {size} bytes, more than {MAX_LAYOUT_BYTES}")
        raw = p.read_bytes()
    except OSError as exc:
        raise LayoutError(
            f"layout file {str(p)!r}: cannot read it: {exc.strerror or exc}"
        ) from None
    try:
        text = raw.decode("utf-8")
        data = tomllib.loads(text) if suffix == ".toml" else json.loads(text)
    except (UnicodeDecodeError, tomllib.TOMLDecodeError, json.JSONDecodeError) as exc:
        raise LayoutError(
            f"layout file {str(p)!r}: not valid {suffix[1:].upper()}: {exc}"
        ) from None
    return parse_layout(data, source=str(p))
