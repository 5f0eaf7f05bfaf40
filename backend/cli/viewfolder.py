"""A folder of trained views for ``visioncell models import`` (:mod:`backend.cli.models`):
the viewpoint of each image from its name or the folder's ``manifest.json``, its mask and
its yaw."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path
from typing import Any

_VP_PATTERNS = (
    (re.compile(r"(^|[^a-z0-9])(top|vp1|v1|view1)([^a-z0-9]|$)"), 1),
    (re.compile(r"(^|[^a-z0-9])(inner|vp2|v2|view2)([^a-z0-9]|$)"), 2),
    (re.compile(r"(^|[^a-z0-9])(outer|vp3|v3|view3)([^a-z0-9]|$)"), 3),
)
_SUFFIXES = (".png", ".jpg", ".jpeg")
MAX_IMPORT_FILES = 500


def parse_viewpoint(name: str) -> int | None:
    """The viewpoint a file name names (module docstring), or None."""
    stem = Path(name).stem.lower()
    found = {vp for pat, vp in _VP_PATTERNS if pat.search(stem)}
    return found.pop() if len(found) == 1 else None


def read_folder(folder: Path) -> list[dict[str, Any]]:
    """The images of ``folder`` with their viewpoint, mask and yaw (module docstring).

    Raises ``ValueError`` naming the file whose viewpoint is unknown or whose manifest
    entry is malformed.
    """
    if not folder.is_dir():
        raise ValueError(f"{str(folder)!r} is not a folder")
    manifest = folder / "manifest.json"
    if manifest.exists():
        try:
            entries = json.loads(manifest.read_text())
        except json.JSONDecodeError as exc:
            raise ValueError(f"{str(manifest)!r} is not JSON: {exc}") from None
        if not isinstance(entries, list) or not entries:
            raise ValueError(f"{str(manifest)!r} must hold a non-empty list of entries")
        out = []
        for k, e in enumerate(entries):
            if not isinstance(e, dict) or not isinstance(e.get("file"), str):
                raise ValueError(f"manifest entry {k} must be an object with a 'file', got {e!r}")
            vp = e.get("viewpoint")
            if isinstance(vp, bool) or vp not in (1, 2, 3):
                raise ValueError(f"manifest entry {k} ({e['file']}): viewpoint must be 1, 2 or 3")
            yaw = e.get("yaw_rad", 0.0)
            if isinstance(yaw, bool) or not isinstance(yaw, int | float) or not math.isfinite(yaw):
                raise ValueError(f"manifest entry {k} ({e['file']}): yaw_rad must be finite")
            mask = e.get("mask")
            if mask is not None and not isinstance(mask, str):
                raise ValueError(f"manifest entry {k} ({e['file']}): mask must be a file name")
            for f in (e["file"], mask):
                if f is not None and (Path(f).name != f or not (folder / f).is_file()):
                    raise ValueError(f"manifest entry {k}: no file {f!r} in the folder")
            out.append(
                {
                    "file": folder / e["file"],
                    "viewpoint": vp,
                    "yaw_rad": float(yaw),
                    "mask": None if mask is None else folder / mask,
                }
            )
        return out
    files = sorted(
        p
        for p in folder.iterdir()
        if p.suffix.lower() in _SUFFIXES and not p.stem.lower().endswith("_mask")
    )
    if not files:
        raise ValueError(f"no PNG or JPEG images in {str(folder)!r}")
    out = []
    for p in files:
        vp = parse_viewpoint(p.name)
        if vp is None:
            raise ValueError(
                f"{p.name!r} names no viewpoint: put top/vp1, vp2/inner or vp3/outer in its "
                "name, or list it in a manifest.json"
            )
        mask = next((q for q in (p.with_name(p.stem + "_mask.png"),) if q.is_file()), None)
        out.append({"file": p, "viewpoint": vp, "yaw_rad": 0.0, "mask": mask})
    return out
