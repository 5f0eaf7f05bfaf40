"""Time filters in query strings are strict ISO 8601 instants with a zone, bounded after the
offset is applied: a value whose offset pushes it past year 9999 (or before year 1) in UTC,
a number, or a value without a zone is a 422 naming the parameter and quoting the value,
on every route that takes one (reports, inspections, audit), never a 500."""

from __future__ import annotations

from urllib.parse import quote

import pytest

from backend.instants import parse_instant
from backend.reports.filters import parse_time
from vision.errors import InvalidInput

# Every test here only reads or is refused before anything is stored.
pytestmark = pytest.mark.shared_app

PAST_9999 = "9999-12-31T23:59:59.999999-01:00"
BEFORE_1 = "0001-01-01T00:00:00+01:00"
REPORTS = ("summary", "timeseries", "confusion", "export.csv", "export.jsonl")


def _routes() -> list[tuple[str, str]]:
    out = [(f"/api/reports/{r}", p) for r in REPORTS for p in ("from", "to")]
    out += [("/api/inspections", p) for p in ("since", "until")]
    out += [("/api/audit", p) for p in ("since", "until")]
    return out


@pytest.mark.parametrize(
    ("value", "needle"),
    [
        (PAST_9999, "must lie within the years 1970..2199 in UTC"),
        (BEFORE_1, "must lie within the years 1970..2199 in UTC"),
        ("2026-01-01T00:00:00", "must be an ISO-8601 date-time with a zone"),
        ("2026-01-01", "must be an ISO-8601 date-time with a zone"),
        ("0.5", "must be an ISO-8601 date-time with a zone"),
        ("1764000000", "must be an ISO-8601 date-time with a zone"),
        ("true", "must be an ISO-8601 date-time with a zone"),
        ("2026-02-30T00:00:00Z", "must be a valid ISO-8601 date-time"),
    ],
)
def test_every_time_filter_refuses_with_a_422(client, headers, value: str, needle: str) -> None:
    for path, param in _routes():
        r = client.get(f"{path}?{param}={quote(value)}", headers=headers["engineer"])
        assert r.status_code == 422, (path, param, r.status_code, r.text)
        body = r.json()
        assert body["error"] == "validation_error", body
        assert body["detail"].startswith(f"{param}: {needle}"), (path, body)
        assert repr(value) in body["detail"], body


def test_zoned_instants_are_accepted_everywhere(client, headers) -> None:
    for value in ("2026-01-01T00:00:00Z", "2026-01-01T02:00:00+02:00", "2026-01-01 00:00z"):
        for path, param in _routes():
            r = client.get(f"{path}?{param}={quote(value)}", headers=headers["engineer"])
            assert r.status_code == 200, (path, param, value, r.text)


def test_the_offset_is_applied_before_the_bound() -> None:
    assert parse_instant("2199-12-31T23:00:00-00:59", "t").year == 2199
    with pytest.raises(InvalidInput, match=r"^t must lie within the years .*got '2199-12-31T23"):
        parse_instant("2199-12-31T23:30:00-01:00", "t")
    with pytest.raises(InvalidInput, match="t must be an ISO-8601 date-time"):
        parse_instant(0.5, "t")
    with pytest.raises(InvalidInput, match="t must be an ISO-8601 date-time"):
        parse_instant(True, "t")


def test_the_cli_filter_refuses_the_overflow_too() -> None:
    with pytest.raises(InvalidInput, match="to must be within the years"):
        parse_time(PAST_9999, "to")
