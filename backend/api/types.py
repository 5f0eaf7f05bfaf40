"""Bounded value types of the API: every number finite, strict and within a physical range.

Booleans are not numbers here (``strict=True``), ``Infinity``/``NaN`` are refused
(``allow_inf_nan=False``) and every value has the range an engineer would expect of a real
cell, stated in the schema so that OpenAPI shows it.  Ids are checked against the
database's integer range in one place (:data:`DbId`), so a huge id is a 422, never an
overflow inside the database driver.
"""

from __future__ import annotations

import math
from datetime import datetime
from typing import Annotated, Any

from fastapi import Path, Query
from pydantic import BeforeValidator, Field

from backend.instants import EXAMPLE, MAX_INSTANT_LENGTH, MAX_YEAR, MIN_YEAR, instant
from robot.kinematics.analytic import MAX_ABS_POSITION_M
from robot.trajectory import MIN_SPEED

__all__ = [
    "MAX_ABS_JOINT_API_RAD",
    "MAX_DB_ID",
    "MAX_NAME_LENGTH",
    "ApproachComponent",
    "DbId",
    "DbIdQuery",
    "DbIndex",
    "InstantQuery",
    "JointList",
    "JointRad",
    "Limit",
    "Matrix4",
    "Metres",
    "NameStr",
    "Offset",
    "RollRad",
    "Speed",
    "StrictBool",
    "bounded_float",
    "bounded_int",
    "instant_query",
]

#: Largest id a row can have: SQLite's INTEGER and PostgreSQL's BIGINT are signed 64-bit.
MAX_DB_ID = 2**63 - 1
#: Longest name in a path (users, lights, boards, jobs).
MAX_NAME_LENGTH = 128
#: Joint values accepted by the API, radians: one turn either way covers every range of the
#: arm (the joint-limit gate then says which joint is out of its own range).
MAX_ABS_JOINT_API_RAD = 2.0 * math.pi


def _examples(examples: list[Any] | None) -> dict[str, Any]:
    # Only set when given: a ``Field(examples=None)`` would count as set when merged.
    return {} if examples is None else {"examples": examples}


def bounded_float(
    lo: float, hi: float, description: str, *, examples: list[Any] | None = None
) -> object:
    """A ``Field`` for a strict, finite float in ``[lo, hi]``."""
    return Field(
        strict=True,
        allow_inf_nan=False,
        ge=lo,
        le=hi,
        description=description,
        **_examples(examples),
    )


def bounded_int(lo: int, hi: int, description: str, *, examples: list[Any] | None = None) -> object:
    """A ``Field`` for a strict integer in ``[lo, hi]`` (booleans refused)."""
    return Field(strict=True, ge=lo, le=hi, description=description, **_examples(examples))


DbId = Annotated[int, Path(ge=1, le=MAX_DB_ID, description="Row id, 1 .. 2^63 - 1", examples=[1])]
DbIndex = Annotated[int, Path(ge=0, le=MAX_DB_ID, description="Index, 0 .. 2^63 - 1", examples=[0])]
DbIdQuery = Annotated[int | None, Query(ge=1, le=MAX_DB_ID, description="Row id, 1 .. 2^63 - 1")]
Limit = Annotated[int, Query(ge=1, le=500, description="Page size, 1 .. 500")]
Offset = Annotated[
    int, Query(ge=0, le=MAX_DB_ID, description="Rows to skip before the page, 0 .. 2^63 - 1")
]
NameStr = Annotated[
    str, Path(min_length=1, max_length=MAX_NAME_LENGTH, description="A name, 1..128 characters")
]


def _instant(value: object) -> datetime:
    # Query values arrive as text; the validator refuses anything but a zoned ISO 8601
    # instant, and bounds it after the offset is applied (:mod:`backend.instants`).
    return instant(value, zone_required=True)


def instant_query(description: str, *, alias: str | None = None) -> Any:
    """An optional query parameter holding an instant: ISO 8601 with a zone, as aware UTC
    within the years the database holds (422 quoting the value otherwise)."""
    return Annotated[
        datetime | None,
        BeforeValidator(_instant),
        Query(
            alias=alias,
            # Checked by the validator (a constraint here would apply to the datetime).
            json_schema_extra={"maxLength": MAX_INSTANT_LENGTH},
            description=f"{description}: ISO 8601 with a zone, e.g. {EXAMPLE} "
            f"(years {MIN_YEAR}..{MAX_YEAR} in UTC)",
            examples=[EXAMPLE],
        ),
    ]


#: An optional instant in a query string (see :func:`instant_query`).
InstantQuery = instant_query("An instant")

StrictBool = Annotated[bool, Field(strict=True)]
JointRad = Annotated[
    float,
    bounded_float(
        -MAX_ABS_JOINT_API_RAD, MAX_ABS_JOINT_API_RAD, "Joint value, radians, within one turn"
    ),
]


def _short(v: object) -> str:
    text = repr(v)
    return text if len(text) <= 80 else text[:77] + "..."


def _five(v: object) -> object:
    if isinstance(v, list) and len(v) != 5:
        raise ValueError(f"joints must have 5 values (q1..q5), got {len(v)}")
    return v


def _four_by_four(v: object) -> object:
    if v is not None and not (
        isinstance(v, list) and len(v) == 4 and all(isinstance(r, list) and len(r) == 4 for r in v)
    ):
        raise ValueError(f"must be a 4x4 matrix (4 rows of 4 numbers), got {_short(v)}")
    return v


JointList = Annotated[
    list[JointRad],
    BeforeValidator(_five),
    Field(
        min_length=5,
        max_length=5,
        description="q1..q5 in radians",
        examples=[[0.0, 1.5708, -1.5708, 0.0, 0.0]],
    ),
]
Metres = Annotated[
    float,
    bounded_float(
        -MAX_ABS_POSITION_M,
        MAX_ABS_POSITION_M,
        f"Position in the base frame, metres, within +-{MAX_ABS_POSITION_M:g} m",
    ),
]
ApproachComponent = Annotated[
    float, bounded_float(-1.0, 1.0, "Component of the unit approach direction")
]
RollRad = Annotated[
    float,
    bounded_float(
        -2.0 * math.pi, 2.0 * math.pi, "Rotation about the approach axis, radians, within +-2 pi"
    ),
]
Speed = Annotated[
    float,
    bounded_float(
        MIN_SPEED, 1.0, f"Fraction of the arm's speed limits, {MIN_SPEED} .. 1", examples=[0.5]
    ),
]
Matrix4 = Annotated[
    list[
        list[
            Annotated[float, bounded_float(-10.0, 10.0, "Matrix entry (metres in the last column)")]
        ]
    ],
    BeforeValidator(_four_by_four),
    Field(description="A rigid transform, 4x4, rotation and translation in metres"),
]
