"""The OpenAPI documents every error the API answers: 400 (a malformed request) on every
operation, and 415 (a media type or a file format not accepted) on every operation that
takes a body, each with the ``{"error", "detail"}`` schema."""

from __future__ import annotations

from backend.app import create_app
from tests.utils.factories import make_settings


def test_400_everywhere_and_415_wherever_a_body_is_taken(tmp_path, client, headers) -> None:
    spec = create_app(make_settings(tmp_path)).openapi()
    ops = [
        (method, path, op)
        for path, item in spec["paths"].items()
        for method, op in item.items()
        if method in ("get", "post", "put", "patch", "delete")
    ]
    assert len(ops) > 50
    for method, path, op in ops:
        answers = op["responses"]
        assert "400" in answers, (method, path)
        ref = answers["400"]["content"]["application/json"]["schema"]["$ref"]
        assert ref.endswith("/ErrorOut"), (method, path, ref)
        if "requestBody" in op:
            assert "415" in answers, (method, path)
            ref = answers["415"]["content"]["application/json"]["schema"]["$ref"]
            assert ref.endswith("/ErrorOut"), (method, path, ref)
    upload = ("post", "/api/calibration/sessions/{session_id}/samples")
    assert upload in {(m, p) for m, p, op in ops if "requestBody" in op}
    # That upload answers 415 as documented, with the documented body.
    board = {"type": "chessboard", "cols": 9, "rows": 6, "square_mm": 30}
    r = client.post("/api/calibration/sessions", json={"kind": "intrinsic", "board": board},
                    headers=headers["engineer"])  # fmt: skip
    assert r.status_code == 201, r.text
    sid = r.json()["session"]["id"]
    r = client.post(f"/api/calibration/sessions/{sid}/samples",
                    files=[("images", ("notes.txt", b"hello", "text/plain"))],
                    headers=headers["engineer"])  # fmt: skip
    assert r.status_code == 415 and r.json()["error"] == "unsupported_media_type", r.text
