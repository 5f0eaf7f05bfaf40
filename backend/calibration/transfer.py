"""Calibration documents: a calibration exported from one cell (or written by another tool)
and imported into another.

A document is one JSON object::

    {"format": "visioncell-calibration", "version": 1, "kind": "intrinsic" | "hand_eye",
     "parameters": {...}, "sample_count": 12, "rms_px": 0.21, "source": {...}}

``parameters`` of an intrinsic calibration are ``K`` (3x3, pixels), ``dist`` (OpenCV's
order ``k1, k2, p1, p2[, k3[, k4, k5, k6[, s1..s4[, tx, ty]]]]``; the cell's camera model
is Brown-Conrady with five terms, so the terms after ``k3`` must be zero) and
``image_size`` (``[width, height]``); those of a hand-eye calibration are ``T_ee_cam``
(4x4, metres) and optionally the intrinsics it was solved with (``K``, ``dist``,
``image_size``).  ``source`` says where the calibration came from (free-form, small).

:func:`check_document` is the one validation, used by the API before storing and by the
CLI before sending: every bad value is named.  :func:`import_calibration` stores a checked
document as a new calibration row of the cell (audited, optionally activated in the same
unit of work); :func:`export_document` is its inverse.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from sqlalchemy import select
from sqlalchemy.ext.asyncio import AsyncSession

from backend import audit
from backend.calibration.solving import activate
from backend.db.models import Calibration, CalibrationKind
from backend.db.models import Cell as CellRow
from vision.calibration import check_poses
from vision.camera import check_dist, check_K
from vision.errors import InvalidInput

__all__ = [
    "DIST_LENGTHS",
    "FORMAT",
    "MAX_ABS_DIST",
    "MAX_FOCAL_PX",
    "MAX_IMAGE_SIDE_PX",
    "MAX_SOURCE_BYTES",
    "MAX_TRANSLATION_M",
    "MIN_FOCAL_PX",
    "ROTATION_TOL",
    "VERSION",
    "CheckedCalibration",
    "check_document",
    "export_document",
    "import_calibration",
]

FORMAT = "visioncell-calibration"
VERSION = 1
#: Focal lengths accepted, pixels (a fisheye of a few pixels to a long lens on a big sensor).
MIN_FOCAL_PX = 1.0
MAX_FOCAL_PX = 1e6
#: Largest image side, pixels.
MAX_IMAGE_SIDE_PX = 65_535
#: Lengths of OpenCV's distortion vectors: Brown-Conrady, + k3, rational, thin prism, tilted.
DIST_LENGTHS = (4, 5, 8, 12, 14)
#: Largest distortion coefficient in absolute value.
MAX_ABS_DIST = 1e3
#: Largest camera offset from the flange, metres.
MAX_TRANSLATION_M = 2.0
#: Largest deviation of ``R^T R`` from the identity (element-wise) of a hand-eye rotation.
ROTATION_TOL = 1e-4
#: Largest ``source`` object, bytes of JSON.
MAX_SOURCE_BYTES = 4096
#: Largest ``sample_count``.
MAX_SAMPLES = 100_000
#: Largest ``rms_px``.
MAX_RMS_PX = 1e3

_FIELDS = ("format", "version", "kind", "parameters", "sample_count", "rms_px", "source")
_INTRINSIC_KEYS = ("K", "dist", "image_size")
#: The parameters a document of each kind may have.
_KEYS = {
    CalibrationKind.intrinsic: _INTRINSIC_KEYS,
    CalibrationKind.hand_eye: ("T_ee_cam", *_INTRINSIC_KEYS),
}


@dataclass(frozen=True)
class CheckedCalibration:
    """A checked document: what :func:`import_calibration` stores."""

    kind: CalibrationKind
    parameters: dict[str, Any]
    sample_count: int
    rms_px: float | None
    source: dict[str, Any]


def _number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


def _matrix(value: Any, name: str, rows: int, cols: int) -> list[list[float]]:
    if (
        not isinstance(value, list)
        or len(value) != rows
        or not all(isinstance(r, list) and len(r) == cols for r in value)
    ):
        raise InvalidInput(f"{name} must be a {rows}x{cols} list of rows, got {value!r:.200}")
    for i, r in enumerate(value):
        for j, v in enumerate(r):
            if not _number(v) or not math.isfinite(v):
                raise InvalidInput(f"{name}[{i}][{j}] must be a finite number, got {v!r:.40}")
    return [[float(v) for v in r] for r in value]


def _image_size(value: Any, name: str) -> list[int]:
    if not isinstance(value, list) or len(value) != 2:
        raise InvalidInput(f"{name} must be [width, height], got {value!r:.100}")
    for k, v in enumerate(value):
        if not isinstance(v, int) or isinstance(v, bool) or not 1 <= v <= MAX_IMAGE_SIDE_PX:
            raise InvalidInput(
                f"{name}[{k}] must be a whole number of pixels in 1..{MAX_IMAGE_SIDE_PX}, "
                f"got {v!r:.40}"
            )
    return [int(value[0]), int(value[1])]


def _intrinsics(p: dict[str, Any], where: str) -> dict[str, Any]:
    """``K``, ``dist`` and ``image_size`` of ``p`` checked; ``dist`` as the cell's five terms."""
    for key in _INTRINSIC_KEYS:
        if key not in p:
            raise InvalidInput(f"{where}.{key} is missing")
    w, h = _image_size(p["image_size"], f"{where}.image_size")
    K = _matrix(p["K"], f"{where}.K", 3, 3)
    fx, fy, cx, cy = K[0][0], K[1][1], K[0][2], K[1][2]
    for name, f in (("fx (K[0][0])", fx), ("fy (K[1][1])", fy)):
        if not MIN_FOCAL_PX <= f <= MAX_FOCAL_PX:
            raise InvalidInput(
                f"{where}.K: {name} must be in {MIN_FOCAL_PX:g}..{MAX_FOCAL_PX:g} px, got {f!r}"
            )
    if abs(K[0][1]) > fx:
        raise InvalidInput(f"{where}.K: the skew K[0][1] must be at most fx, got {K[0][1]!r}")
    if not 0.0 <= cx <= w:
        raise InvalidInput(f"{where}.K: cx (K[0][2]) must lie in the image (0..{w}), got {cx!r}")
    if not 0.0 <= cy <= h:
        raise InvalidInput(f"{where}.K: cy (K[1][2]) must lie in the image (0..{h}), got {cy!r}")
    try:
        check_K(K)  # the camera model's own rule: upper triangular, last row (0, 0, 1)
    except ValueError as exc:
        raise InvalidInput(f"{where}.K: {exc}") from None
    d = p["dist"]
    if not isinstance(d, list) or len(d) not in DIST_LENGTHS:
        raise InvalidInput(
            f"{where}.dist must be a list of {', '.join(map(str, DIST_LENGTHS))} coefficients "
            f"(OpenCV's order), got {d!r:.200}"
        )
    for k, v in enumerate(d):
        if not _number(v) or not math.isfinite(v) or abs(v) > MAX_ABS_DIST:
            raise InvalidInput(
                f"{where}.dist[{k}] must be a finite number within +-{MAX_ABS_DIST:g}, "
                f"got {v!r:.40}"
            )
    extra = [k for k in range(5, len(d)) if d[k] != 0.0]
    if extra:
        raise InvalidInput(
            f"{where}.dist[{extra[0]}] is {d[extra[0]]!r}: the cell's camera model has the "
            "five terms k1, k2, p1, p2, k3; terms after k3 (rational, thin prism, tilt) must "
            "be 0 (calibrate with them held at zero)"
        )
    dist = check_dist(d[:5]).tolist()  # four terms: k3 = 0
    return {"K": K, "dist": dist, "image_size": [w, h]}


def _hand_eye(p: dict[str, Any], where: str) -> dict[str, Any]:
    if "T_ee_cam" not in p:
        raise InvalidInput(f"{where}.T_ee_cam is missing")
    T = _matrix(p["T_ee_cam"], f"{where}.T_ee_cam", 4, 4)
    try:
        check_poses(np.asarray(T)[None], f"{where}.T_ee_cam", tol=ROTATION_TOL)
    except ValueError as exc:
        rule = f" (a rotation: |R^T R - I| <= {ROTATION_TOL:g}, det(R) = +1)"
        raise InvalidInput(str(exc) + (rule if "rotation" in str(exc) else "")) from None
    t = math.sqrt(sum(T[i][3] ** 2 for i in range(3)))
    if t > MAX_TRANSLATION_M:
        raise InvalidInput(
            f"{where}.T_ee_cam: the camera is {t:.3f} m from the flange; at most "
            f"{MAX_TRANSLATION_M:g} m (the translation is in metres)"
        )
    out: dict[str, Any] = {"T_ee_cam": T}
    given = [k for k in _INTRINSIC_KEYS if k in p]
    if given:  # the intrinsics the hand-eye transform was solved with: all three or none
        out.update(_intrinsics(p, where))
    return out


def check_document(doc: Any) -> CheckedCalibration:
    """The calibration of an exported document, every value checked.

    Raises
    ------
    InvalidInput
        Naming the first bad value: a wrong format or version, an unknown field or kind,
        a matrix of the wrong shape, a value out of its physical range, a rotation that is
        not one.  Nothing is stored by the caller then.
    """
    if not isinstance(doc, dict):
        raise InvalidInput(f"a calibration document is a JSON object, got {type(doc).__name__}")
    unknown = sorted(set(doc) - set(_FIELDS))
    if unknown:
        raise InvalidInput(f"unknown field {unknown[0]!r}; a document has {', '.join(_FIELDS)}")
    if doc.get("format") != FORMAT:
        raise InvalidInput(f"format must be {FORMAT!r}, got {doc.get('format')!r:.80}")
    if doc.get("version") != VERSION or isinstance(doc.get("version"), bool):
        raise InvalidInput(
            f"version must be {VERSION} (this cell reads version {VERSION}), "
            f"got {doc.get('version')!r:.40}"
        )
    kinds = [k.value for k in CalibrationKind]
    if doc.get("kind") not in kinds:
        raise InvalidInput(f"kind must be one of {kinds}, got {doc.get('kind')!r:.80}")
    kind = CalibrationKind(doc["kind"])
    p = doc.get("parameters")
    if not isinstance(p, dict):
        raise InvalidInput(f"parameters must be an object, got {p!r:.100}")
    allowed = _KEYS[kind]
    bad = sorted(set(p) - set(allowed))
    if bad:
        raise InvalidInput(
            f"parameters.{bad[0]} is not a parameter of a {kind.value} calibration "
            f"(it has {', '.join(allowed)})"
        )
    params = (
        _intrinsics(p, "parameters")
        if kind is CalibrationKind.intrinsic
        else _hand_eye(p, "parameters")
    )
    n = doc.get("sample_count", 0)
    if not isinstance(n, int) or isinstance(n, bool) or not 0 <= n <= MAX_SAMPLES:
        raise InvalidInput(
            f"sample_count must be a whole number in 0..{MAX_SAMPLES}, got {n!r:.40}"
        )
    rms = doc.get("rms_px")
    if rms is not None and (not _number(rms) or not 0.0 <= rms <= MAX_RMS_PX):
        raise InvalidInput(f"rms_px must be a number in 0..{MAX_RMS_PX:g} or null, got {rms!r:.40}")
    source = doc.get("source") or {}
    if not isinstance(source, dict):
        raise InvalidInput(f"source must be an object, got {source!r:.100}")
    size = len(json.dumps(source, allow_nan=False, default=str))
    if size > MAX_SOURCE_BYTES:
        raise InvalidInput(f"source must take at most {MAX_SOURCE_BYTES} bytes of JSON, got {size}")
    return CheckedCalibration(kind, params, int(n), None if rms is None else float(rms), source)


async def export_document(session: AsyncSession, cal: Calibration) -> dict[str, Any]:
    """The document of a stored calibration (:func:`check_document` takes it back)."""
    p = cal.parameters
    keys = _KEYS[cal.kind]
    cell = await session.scalar(select(CellRow.name).where(CellRow.id == cal.cell_id))
    source: dict[str, Any] = {
        "cell": cell,
        "calibration_id": cal.id,
        "session_id": cal.session_id,
        "created_at": cal.created_at.isoformat(),
    }
    if cal.kind is CalibrationKind.hand_eye and p.get("intrinsics_id") is not None:
        source["intrinsics_id"] = p["intrinsics_id"]
    if (previous := (cal.options or {}).get("imported_from")) is not None:
        source["imported_from"] = previous
    return {
        "format": FORMAT,
        "version": VERSION,
        "kind": cal.kind.value,
        "parameters": {k: p[k] for k in keys if k in p},
        "sample_count": cal.sample_count,
        "rms_px": cal.rms_px,
        "source": source,
    }


async def import_calibration(
    session: AsyncSession,
    cell_id: int,
    checked: CheckedCalibration,
    *,
    make_active: bool = False,
    by: audit.By | None = None,
) -> Calibration:
    """Store a checked document as a new calibration of cell ``cell_id`` (audited), and
    activate it in the same unit of work when ``make_active``.

    An imported hand-eye calibration refers to no intrinsic row of this cell: activate the
    imported intrinsics too (``activate`` of a solved one brings them along)."""
    by = by or audit.By()
    params = dict(checked.parameters)
    if checked.kind is CalibrationKind.hand_eye:
        params["intrinsics_id"] = None
    row = Calibration(
        cell_id=cell_id,
        session_id=None,
        kind=checked.kind,
        parameters=params,
        residuals={},
        options={"imported_from": checked.source},
        sample_count=checked.sample_count,
        rms_px=checked.rms_px,
        active=False,
    )
    session.add(row)
    await session.flush()
    audit.record(
        session,
        actor=by.actor,
        kind="calibration",
        entity_id=row.id,
        action="import",
        old=None,
        new={
            "cell_id": cell_id,
            "kind": checked.kind.value,
            "parameters": params,
            "source": checked.source,
        },
        reason=by.reason,
    )
    if make_active:
        await activate(session, row.id, by=by)
    return row
