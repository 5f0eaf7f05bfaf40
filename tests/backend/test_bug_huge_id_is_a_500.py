"""Bug: an id of 2^63 or more answered a text/plain 500 ("Python int too large to convert
to SQLite INTEGER") on every ``{id}`` path and query.  Ids are now checked against the
database's integer range (1 .. 2^63 - 1) by one shared path-parameter type."""

from __future__ import annotations

import pytest

from backend.api.types import MAX_DB_ID

# Every test here only reads or is refused before anything is stored.
pytestmark = pytest.mark.shared_app

HUGE = 2**63  # one past SQLite's and PostgreSQL's BIGINT

PATHS = [
    f"/api/calibration/sessions/{HUGE}",
    f"/api/calibration/sessions/{HUGE}/samples/0/image.png",
    f"/api/calibration/sessions/1/samples/{HUGE}/image.png",
    f"/api/calibration/calibrations/{HUGE}",
    f"/api/calibration/calibrations/{HUGE}/report",
    f"/api/calibration/calibrations/{HUGE}/report/residuals.png",
    f"/api/calibration/calibrations?session_id={HUGE}",
    f"/api/calibration/sessions?offset={HUGE}",
    f"/api/calibration/sessions/{10**30}",
    "/api/calibration/sessions/0",
    "/api/calibration/sessions/-1",
]


@pytest.mark.parametrize("path", PATHS)
def test_out_of_range_id_is_a_json_422(client, headers, path):
    r = client.get(path, headers=headers["viewer"])
    assert r.status_code == 422, r.text
    assert r.headers["content-type"] == "application/json"
    assert r.json()["error"] == "validation_error"
    assert "Input should be" in r.json()["detail"]


@pytest.mark.parametrize(
    ("method", "path"),
    [
        ("post", f"/api/calibration/sessions/{HUGE}/solve"),
        ("post", f"/api/calibration/calibrations/{HUGE}/activate"),
    ],
)
def test_out_of_range_id_in_a_write_is_a_json_422(client, headers, method, path):
    r = client.request(method, path, headers=headers["engineer"])
    assert r.status_code == 422 and r.json()["error"] == "validation_error", r.text


def test_largest_id_is_a_clean_404(client, headers):
    r = client.get(f"/api/calibration/sessions/{MAX_DB_ID}", headers=headers["viewer"])
    assert r.status_code == 404
    assert r.json() == {
        "error": "not_found",
        "detail": f"no calibration session with id {MAX_DB_ID}",
    }
    r = client.get(f"/api/calibration/calibrations/{MAX_DB_ID}/report", headers=headers["viewer"])
    assert r.status_code == 404 and r.json()["error"] == "not_found"
