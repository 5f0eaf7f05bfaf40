"""Field types shared by the answer schemas of the services and of the API."""

from __future__ import annotations

from datetime import datetime
from typing import Annotated

from pydantic import BeforeValidator

__all__ = ["IsoTime"]


def _iso(value: object) -> object:
    return value.isoformat() if isinstance(value, datetime) else value


#: A time as the API writes it: ``datetime.isoformat()`` (``2026-01-02T03:04:05.678+00:00``),
#: read from a ``datetime`` attribute of a row.
IsoTime = Annotated[str, BeforeValidator(_iso)]
