"""Calibration REST API: roles, uploads, bad input, solve jobs, reports, activation."""

from __future__ import annotations

import time

import cv2
import numpy as np
import pytest

BOARD = {"type": "chessboard", "cols": 9, "rows": 6, "square_mm": 30}


def _create(client, headers, kind="intrinsic", board=BOARD):
    r = client.post(
        "/api/calibration/sessions",
        json={"kind": kind, "board": board},
        headers=headers["engineer"],
    )
    assert r.status_code == 201, r.text
    return r.json()["session"]["id"]


def _files(folder, indices=None):
    files = folder.files if indices is None else [folder.files[i] for i in indices]
    return [("images", (f.name, f.read_bytes(), "image/png")) for f in files]


def _upload(client, headers, sid, folder, *, poses=True, indices=None):
    files = _files(folder, indices)
    if poses:
        lines = folder.poses_file.read_text().splitlines()
        if indices is not None:
            lines = [lines[i] for i in indices]
        files.append(("poses", ("poses.txt", "\n".join(lines).encode(), "text/plain")))
    return client.post(
        f"/api/calibration/sessions/{sid}/samples", files=files, headers=headers["engineer"]
    )


def test_reading_needs_a_viewer_and_writing_an_engineer(client, headers):
    assert client.get("/api/calibration/sessions").status_code == 401
    r = client.post(
        "/api/calibration/sessions",
        json={"kind": "intrinsic", "board": BOARD},
        headers=headers["operator"],
    )
    assert r.status_code == 403
    assert r.json() == {
        "error": "forbidden",
        "detail": "this needs the engineer role; user 'test-operator' is operator",
    }
    r = client.get("/api/calibration/sessions", headers=headers["viewer"])
    assert r.status_code == 200 and r.json() == {"data": [], "count": 0}


@pytest.mark.shared_app  # refused: nothing stored, nothing moved
@pytest.mark.parametrize(
    ("body", "detail"),
    [
        (
            {"kind": "intrinsic", "board": {"cols": 9, "rows": 2, "square_mm": 25}},
            "board.rows: Input should be greater than or equal to 3",
        ),
        (
            {"kind": "intrinsic", "board": {"cols": 9, "square_mm": 25}},
            "board: a chessboard needs cols and rows (inner corners)",
        ),
        (
            {
                "kind": "intrinsic",
                "board": {"type": "charuco", "squares_x": 7, "squares_y": 5, "square_mm": 40},
            },
            "board: a ChArUco board needs squares_x, squares_y and marker_mm",
        ),
        (
            {"kind": "hand_eye", "board": {"cols": 8, "rows": 6, "square_mm": 25}},
            "has no unique frame",
        ),
        ({"kind": "stereo", "board": BOARD}, "kind: Input should be 'intrinsic' or 'hand_eye'"),
    ],
)
def test_bad_sessions_are_refused_with_the_reason(client, headers, body, detail):
    r = client.post("/api/calibration/sessions", json=body, headers=headers["engineer"])
    assert r.status_code == 422
    assert (
        r.json()["error"] in ("validation_error", "invalid_value") and detail in r.json()["detail"]
    )


def test_upload_keeps_rejected_images_with_their_reason(client, headers, synthetic_folder):
    sid = _create(client, headers)
    r = _upload(client, headers, sid, synthetic_folder, poses=False)
    assert r.status_code == 201, r.text
    body = r.json()
    assert body["count"] == 9 and body["accepted"] == 8 and body["rejected"] == 1
    assert body["data"][-1] == {
        **body["data"][-1],
        "name": "view_08.png",
        "accepted": False,
        "reason": "no 9x6 chessboard found (sector-based and classic detectors)",
        "corner_count": 0,
    }
    r = client.get(f"/api/calibration/sessions/{sid}", headers=headers["viewer"])
    assert r.status_code == 200 and r.json()["session"]["status"] == "collecting"
    assert [s["index"] for s in r.json()["samples"]] == list(range(9))
    img = client.get(
        f"/api/calibration/sessions/{sid}/samples/0/image.png", headers=headers["viewer"]
    )
    assert img.status_code == 200 and img.headers["content-type"] == "image/png"
    stored = cv2.imdecode(np.frombuffer(img.content, np.uint8), cv2.IMREAD_UNCHANGED)
    np.testing.assert_array_equal(
        stored, cv2.imread(str(synthetic_folder.files[0]), cv2.IMREAD_UNCHANGED)
    )
    r = client.get(
        f"/api/calibration/sessions/{sid}/samples/42/image.png", headers=headers["viewer"]
    )
    assert r.status_code == 404 and r.json()["detail"] == f"session {sid} has no sample 42"


@pytest.mark.parametrize(
    ("name", "content", "status", "detail"),
    [
        (
            "notes.txt",
            b"hello",
            415,
            "file 'notes.txt' is not an image: upload PNG, JPEG, BMP or TIFF files",
        ),
        ("fake.png", b"not really a png", 415, "file 'fake.png' does not decode as an image"),
    ],
)
def test_bad_file_types_are_refused(client, headers, name, content, status, detail):
    sid = _create(client, headers)
    r = client.post(
        f"/api/calibration/sessions/{sid}/samples",
        files=[("images", (name, content, "application/octet-stream"))],
        headers=headers["engineer"],
    )
    assert r.status_code == status and r.json() == {
        "error": "unsupported_media_type",
        "detail": detail,
    }
    assert (
        client.get(f"/api/calibration/sessions/{sid}", headers=headers["viewer"]).json()["samples"]
        == []
    )


def test_hand_eye_upload_needs_one_pose_per_image(client, headers, synthetic_folder):
    sid = _create(client, headers, kind="hand_eye")
    r = _upload(client, headers, sid, synthetic_folder, poses=False, indices=[0, 1])
    assert r.status_code == 422
    assert r.json() == {
        "error": "invalid_value",
        "detail": "sample 'view_00.png' has no robot pose: hand-eye sessions need T_base_ee for every image",
    }
    files = [
        *_files(synthetic_folder, [0, 1]),
        ("poses", ("p.txt", synthetic_folder.poses_file.read_bytes(), "text/plain")),
    ]
    r = client.post(
        f"/api/calibration/sessions/{sid}/samples", files=files, headers=headers["engineer"]
    )
    assert r.status_code == 422
    assert r.json()["detail"] == (
        "poses has 9 poses but 2 images were uploaded: give one pose per image, in the same order"
    )
    files = [*_files(synthetic_folder, [0]), ("poses", ("p.txt", b"1 2 3", "text/plain"))]
    r = client.post(
        f"/api/calibration/sessions/{sid}/samples", files=files, headers=headers["engineer"]
    )
    assert r.status_code == 422 and "p.txt line 1: expected 16 numbers" in r.json()["detail"]
    assert (
        client.get(f"/api/calibration/sessions/{sid}", headers=headers["viewer"]).json()["samples"]
        == []
    )


def test_too_few_views_is_422_and_nothing_is_stored(client, headers, synthetic_folder):
    sid = _create(client, headers)
    assert (
        _upload(client, headers, sid, synthetic_folder, poses=False, indices=[0, 1, 8]).status_code
        == 201
    )
    r = client.post(
        f"/api/calibration/sessions/{sid}/solve",
        json={"activate": True},
        headers=headers["engineer"],
    )
    assert r.status_code == 422
    assert r.json() == {
        "error": "calibration_failed",
        "detail": "need at least 4 images with the board, the session has 2 of 3 "
        "(rejected: view_08.png: no 9x6 chessboard found (sector-based and classic detectors))",
    }
    assert (
        client.get("/api/calibration/calibrations", headers=headers["viewer"]).json()["count"] == 0
    )
    assert client.get("/api/calibration/active", headers=headers["viewer"]).json() == {
        "intrinsic": None,
        "hand_eye": None,
    }


def test_degenerate_motion_is_422(client, headers, synthetic_folder):
    sid = _create(client, headers, kind="hand_eye")
    first = synthetic_folder.poses_file.read_text().splitlines()[0]
    files = [
        *_files(synthetic_folder, range(6)),
        ("poses", ("p.txt", "\n".join([first] * 6).encode(), "text/plain")),
    ]
    assert (
        client.post(
            f"/api/calibration/sessions/{sid}/samples", files=files, headers=headers["engineer"]
        ).status_code
        == 201
    )
    r = client.post(f"/api/calibration/sessions/{sid}/solve?wait=true", headers=headers["engineer"])
    assert r.status_code == 422 and r.json()["error"] == "calibration_failed"
    assert r.json()["detail"].startswith(
        "degenerate motion: the robot orientations differ by at most 0.00 deg"
    )


def _wait_job(client, headers, job_id):
    for _ in range(600):
        job = client.get(f"/api/jobs/{job_id}", headers=headers["viewer"]).json()["job"]
        if job["state"] != "running":
            return job
        time.sleep(0.05)
    raise AssertionError("job did not finish")


def test_solve_job_report_activate_and_history(client, headers, synthetic_folder):
    sid = _create(client, headers, kind="hand_eye")
    assert _upload(client, headers, sid, synthetic_folder).status_code == 201
    r = client.post(
        f"/api/calibration/sessions/{sid}/solve",
        json={"methods": ["tsai", "park"]},
        headers=headers["engineer"],
    )
    assert r.status_code == 202 and r.json()["job"]["kind"] == "calibrate"
    job = _wait_job(client, headers, r.json()["job"]["id"])
    assert job["state"] == "done" and job["progress"] == 1.0, job
    cid, iid = job["result"]["calibration_id"], job["result"]["intrinsic_calibration_id"]
    assert job["result"]["kind"] == "hand_eye" and job["result"]["active"] is False

    report = client.get(f"/api/calibration/calibrations/{cid}/report", headers=headers["viewer"])
    assert report.status_code == 200
    summary = report.json()["summary"]
    assert summary["method"] in ("tsai", "park") and len(summary["per_pose"]) == 8
    assert summary["consistency"]["translation_rms_mm"] < 1.0
    np.testing.assert_allclose(summary["translation_mm"], [40.0, -15.0, 60.0], atol=1.0)
    assert [x["name"] for x in summary["rejected"]] == ["view_08.png"]
    for plot in ("residuals", "coverage", "consistency"):
        png = client.get(report.json()["plots"][plot], headers=headers["viewer"])
        assert (
            png.status_code == 200
            and png.headers["content-type"] == "image/png"
            and png.content[:4] == b"\x89PNG"
        )
    r = client.get(
        f"/api/calibration/calibrations/{iid}/report/consistency.png", headers=headers["viewer"]
    )
    assert (
        r.status_code == 404
        and r.json()["detail"] == f"calibration {iid} is intrinsic: it has no consistency plot"
    )
    r = client.get(
        f"/api/calibration/calibrations/{cid}/report/bogus.png", headers=headers["viewer"]
    )
    assert (
        r.status_code == 404
        and r.json()["detail"] == "no plot 'bogus'; there are residuals, coverage, consistency"
    )

    assert (
        client.post(
            f"/api/calibration/calibrations/{cid}/activate", headers=headers["operator"]
        ).status_code
        == 403
    )
    r = client.post(f"/api/calibration/calibrations/{cid}/activate", headers=headers["engineer"])
    assert r.status_code == 200 and r.json()["calibration"]["active"] is True
    active = client.get("/api/calibration/active", headers=headers["viewer"]).json()
    assert active["hand_eye"]["id"] == cid and active["intrinsic"]["id"] == iid

    # Solve again with other options, wait for it: a new row; the active one stays.
    r = client.post(
        f"/api/calibration/sessions/{sid}/solve?wait=true",
        json={"refine": False, "radial_only": True},
        headers=headers["engineer"],
    )
    assert r.status_code == 200 and r.json()["job"]["state"] == "done"
    hist = client.get(
        "/api/calibration/calibrations?kind=hand_eye", headers=headers["viewer"]
    ).json()
    assert hist["count"] == 2 and hist["data"][1]["id"] == cid and hist["data"][1]["active"]
    assert hist["data"][0]["options"]["hand_eye"]["refine"] is False
    sessions = client.get("/api/calibration/sessions", headers=headers["viewer"]).json()
    assert sessions["count"] == 1 and sessions["data"][0]["status"] == "active"
    assert len(sessions["data"][0]["calibration_ids"]) == 4


def test_unknown_ids_are_404(client, headers):
    r = client.get("/api/calibration/sessions/5", headers=headers["viewer"])
    assert r.status_code == 404 and r.json() == {
        "error": "not_found",
        "detail": "no calibration session with id 5",
    }
    r = client.post("/api/calibration/calibrations/9/activate", headers=headers["engineer"])
    assert r.status_code == 404 and r.json() == {
        "error": "not_found",
        "detail": "no calibration with id 9",
    }


def test_bad_solve_options(client, headers, synthetic_folder):
    sid = _create(client, headers)
    r = client.post(
        f"/api/calibration/sessions/{sid}/solve",
        json={"methods": ["magic"]},
        headers=headers["engineer"],
    )
    assert r.status_code == 422 and "methods must be a non-empty subset of" in r.json()["detail"]
    r = client.post(
        f"/api/calibration/sessions/{sid}/solve", json={"loss": "l3"}, headers=headers["engineer"]
    )
    assert r.status_code == 422 and r.json()["error"] == "validation_error"
