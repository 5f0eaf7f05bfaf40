"""The declarative base of the models, its naming convention and the enumerations the
columns store."""

from __future__ import annotations

import enum
from datetime import datetime
from typing import Any, ClassVar

from sqlalchemy import JSON, Enum, MetaData
from sqlalchemy.orm import DeclarativeBase

from backend.db.types import UTCDateTime

# Stable constraint names so that Alembic migrations are identical on SQLite and PostgreSQL.
NAMING = {
    "ix": "ix_%(column_0_label)s",
    "uq": "uq_%(table_name)s_%(column_0_name)s",
    "ck": "ck_%(table_name)s_%(constraint_name)s",
    "fk": "fk_%(table_name)s_%(column_0_name)s_%(referred_table_name)s",
    "pk": "pk_%(table_name)s",
}


class Base(DeclarativeBase):
    """Declarative base with the naming convention above."""

    metadata = MetaData(naming_convention=NAMING)
    type_annotation_map: ClassVar[dict[Any, Any]] = {
        datetime: UTCDateTime(),
        dict[str, Any]: JSON,
        list[Any]: JSON,
    }


class Role(enum.IntEnum):
    """Access levels, ordered: each role may do everything the lower ones may."""

    viewer = 1
    operator = 2
    engineer = 3


class ObjectKind(enum.StrEnum):
    """Whether recognition needs only the top view (2D) or may visit side views (3D)."""

    two_d = "2d"
    three_d = "3d"


class CalibrationKind(enum.StrEnum):
    """What a calibration solves."""

    intrinsic = "intrinsic"
    hand_eye = "hand_eye"


class Decision(enum.StrEnum):
    """Outcome of one inspection."""

    recognized = "recognized"
    unknown = "unknown"
    failed = "failed"


def _enum(cls: type[enum.Enum], name: str) -> Enum:
    return Enum(
        cls, name=name, native_enum=False, values_callable=lambda c: [m.value for m in c], length=16
    )
