"""API shape: paged lists with the total in ``count``, Public answer schemas and the error
body documented in OpenAPI."""

from __future__ import annotations


def test_count_is_the_total_not_the_page(client, headers):
    eng = headers["engineer"]
    total = client.get("/api/users", headers=eng).json()["count"]
    assert total >= 3
    page = client.get("/api/users?limit=1&offset=1", headers=eng).json()
    assert page["count"] == total and len(page["data"]) == 1
    assert client.get(f"/api/users?offset={total}", headers=eng).json() == {
        "data": [],
        "count": total,
    }
    r = client.get("/api/users?limit=0", headers=eng)
    assert r.status_code == 422 and r.json()["error"] == "validation_error"


def test_calibration_lists_page_with_the_total(client, headers):
    eng = headers["engineer"]
    board = {"type": "chessboard", "cols": 9, "rows": 6, "square_mm": 25}
    for _ in range(3):
        r = client.post(
            "/api/calibration/sessions", json={"kind": "intrinsic", "board": board}, headers=eng
        )
        assert r.status_code == 201, r.text
    page = client.get("/api/calibration/sessions?limit=2", headers=eng).json()
    assert page["count"] == 3 and len(page["data"]) == 2
    page = client.get("/api/calibration/sessions?limit=2&offset=2", headers=eng).json()
    assert page["count"] == 3 and len(page["data"]) == 1


def test_openapi_documents_answers_and_the_error_body(client):
    spec = client.get("/openapi.json").json()
    err = spec["components"]["schemas"]["ErrorOut"]
    assert set(err["required"]) == {"error", "detail"}
    move = spec["paths"]["/api/robot/move"]["post"]
    for status in ("401", "403", "409", "422", "500"):
        ref = move["responses"][status]["content"]["application/json"]["schema"]["$ref"]
        assert ref.endswith("/ErrorOut")
    assert move["responses"]["202"]["content"]["application/json"]["schema"]["$ref"].endswith(
        "/JobOut"
    )
    fk = spec["paths"]["/api/kinematics/fk"]["post"]["responses"]["200"]
    assert fk["content"]["application/json"]["schema"]["$ref"].endswith("/FKOut")
    speed = spec["components"]["schemas"]["MoveIn"]["properties"]["speed"]["anyOf"][0]
    assert speed["minimum"] == 0.01 and speed["maximum"] == 1.0
    sid = next(
        p
        for p in spec["paths"]["/api/calibration/sessions/{session_id}"]["get"]["parameters"]
        if p["name"] == "session_id"
    )
    assert sid["schema"]["maximum"] == 2**63 - 1 and sid["schema"]["minimum"] == 1
