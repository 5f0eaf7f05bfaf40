"""Instants given by a user (API query parameters, CLI options): strict ISO 8601, bounded.

A time filter is compared with the database's UTC timestamps, so it is converted to UTC
here, once; the conversion itself can leave the calendar (``9999-12-31T23:59:59-01:00`` is
past year 9999 in UTC), and a value without a zone is ambiguous.  :func:`parse_instant`
refuses both with :class:`~vision.errors.InvalidInput` quoting the value, and bounds the
year after the offset is applied, so no database driver ever sees an out-of-range or naive
date-time.
"""

from __future__ import annotations

import re
from datetime import UTC, datetime

from vision.errors import InvalidInput

__all__ = ["EXAMPLE", "MAX_INSTANT_LENGTH", "MAX_YEAR", "MIN_YEAR", "instant", "parse_instant"]

#: Earliest and latest UTC year accepted (inclusive): the cell's records all lie in between.
MIN_YEAR, MAX_YEAR = 1970, 2199
#: Longest accepted text, characters (``2026-01-31T08:00:00.123456+02:00`` is 32).
MAX_INSTANT_LENGTH = 40
#: Calendar date, time to the minute at least (seconds and microseconds optional), and a zone.
_ZONED = re.compile(
    r"^\d{4}-\d{2}-\d{2}[T ]\d{2}:\d{2}(?::\d{2}(?:\.\d{1,6})?)?(?P<zone>[Zz]|[+-]\d{2}:\d{2})$"
)
#: The same without a zone, or a date alone (only where UTC is the stated default).
_LOCAL = re.compile(r"^\d{4}-\d{2}-\d{2}(?:[T ]\d{2}:\d{2}(?::\d{2}(?:\.\d{1,6})?)?)?$")
#: An instant as the messages show it.
EXAMPLE = "2026-01-31T08:00:00Z"


def parse_instant(value: object, name: str, *, zone_required: bool = True) -> datetime:
    """``value`` as an aware UTC datetime within the years :data:`MIN_YEAR`..:data:`MAX_YEAR`.

    Parameters
    ----------
    value : str or datetime
        ISO 8601 text with a zone (``Z`` or ``+HH:MM``), e.g. ``2026-01-31T08:00:00Z``;
        numbers, booleans and other types are refused.  An aware datetime is accepted too.
    name : str
        The parameter's name, quoted in the error.
    zone_required : bool
        False: text without a zone (or a date alone) is taken as UTC (the CLI's reports).

    Raises
    ------
    InvalidInput
        Naming ``name`` and quoting the value.
    """
    try:
        return instant(value, zone_required=zone_required)
    except ValueError as exc:
        raise InvalidInput(f"{name} {exc}, got {_q(value)}") from None


def instant(value: object, *, zone_required: bool = True) -> datetime:
    """:func:`parse_instant` raising a bare ``ValueError`` whose text starts with "must"
    and neither names the parameter nor quotes the value (a schema validator's message)."""
    example = f"(e.g. {EXAMPLE})"
    if isinstance(value, datetime):
        t = value
        if t.tzinfo is None and zone_required:
            raise ValueError(f"must carry a time zone {example}")
    elif isinstance(value, str) and len(value) <= MAX_INSTANT_LENGTH:
        text = value.strip()
        if not (_ZONED.match(text) or (not zone_required and _LOCAL.match(text))):
            zone = "with a zone " if zone_required else ""
            raise ValueError(f"must be an ISO-8601 date-time {zone}{example}")
        try:
            t = datetime.fromisoformat(text.replace("z", "Z").replace("Z", "+00:00"))
        except ValueError:
            raise ValueError(f"must be a valid ISO-8601 date-time {example}") from None
    else:
        raise ValueError(
            f"must be an ISO-8601 date-time of at most {MAX_INSTANT_LENGTH} characters {example}"
        )
    try:
        t = t.replace(tzinfo=UTC) if t.tzinfo is None else t.astimezone(UTC)
    except OverflowError:  # the offset pushed it past year 1 or 9999
        raise ValueError(f"must lie within the years {MIN_YEAR}..{MAX_YEAR} in UTC") from None
    if not MIN_YEAR <= t.year <= MAX_YEAR:
        raise ValueError(f"must lie within the years {MIN_YEAR}..{MAX_YEAR} in UTC")
    return t


def _q(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."
