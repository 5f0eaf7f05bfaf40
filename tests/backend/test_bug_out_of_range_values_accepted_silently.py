"""Bug: values accepted silently: booleans as joint angles or speed, ``1e308`` joints in FK
(answered ``null``), a roll of ``1e308``, a board at ``x = 1e308``, a board of 100000 x
100000 corners.  The schemas are strict and bounded; the core functions validate too."""

from __future__ import annotations

import math

import pytest

from robot.kinematics import fk, ik
from robot.model import ASEA
from vision.calibration import CharucoBoard, Chessboard

# Every test here only reads or is refused before anything is stored.
pytestmark = pytest.mark.shared_app

READY = [0.0, 1.2, -1.4, -0.5, 0.0]
POSE = {"x": 0.8, "y": 0.0, "z": 1.0, "u": 0.0, "w": -1.0}


@pytest.mark.parametrize(
    ("path", "body", "fragment"),
    [
        (
            "/api/kinematics/fk",
            {"joints": [True, 1.2, -1.4, -0.5, 0.0]},
            "joints.0: Input should be a valid number",
        ),
        (
            "/api/kinematics/fk",
            {"joints": [1e308, 1.2, -1.4, -0.5, 0.0]},
            "joints.0: Input should be less than or equal to 6.28",
        ),
        (
            "/api/kinematics/fk",
            {"joints": [0.0, 1.2, -1.4, -0.5, -1e308]},
            "joints.4: Input should be greater than or equal to -6.28",
        ),
        (
            "/api/kinematics/ik",
            {"pose": POSE, "roll": 1e308},
            "roll: Input should be less than or equal to 6.28",
        ),
        (
            "/api/kinematics/ik",
            {"pose": POSE, "roll": False},
            "roll: Input should be a valid number",
        ),
        (
            "/api/kinematics/ik",
            {"pose": {**POSE, "x": 1e308}},
            "pose.x: Input should be less than or equal to 5",
        ),
        ("/api/kinematics/ik", {"pose": {**POSE, "u": 0.6}}, "(u, w) must be a unit vector"),
        (
            "/api/robot/move",
            {"joints": READY, "speed": True},
            "speed: Input should be a valid number",
        ),
        (
            "/api/robot/move",
            {"joints": [False, 1.2, -1.4, -0.5, 0.0]},
            "joints.0: Input should be a valid number",
        ),
        (
            "/api/robot/move",
            {"pose": POSE, "roll": 1e308},
            "roll: Input should be less than or equal to 6.28",
        ),
    ],
)
def test_bad_numbers_are_refused(client, headers, path, body, fragment):
    r = client.post(path, json=body, headers=headers["operator"])
    assert r.status_code == 422, r.text
    assert r.json()["error"] == "validation_error" and fragment in r.json()["detail"], r.text


def test_fk_answers_numbers_never_null(client, headers):
    r = client.post("/api/kinematics/fk", json={"joints": READY}, headers=headers["viewer"])
    assert r.status_code == 200
    assert all(math.isfinite(v) for v in r.json()["pose"].values())


@pytest.mark.parametrize(
    "board",
    [
        {"type": "chessboard", "cols": 100000, "rows": 100000, "square_mm": 25},
        {"type": "chessboard", "cols": 9, "rows": 6, "square_mm": 1e308},
        {"type": "chessboard", "cols": True, "rows": 6, "square_mm": 25},
        {"type": "chessboard", "cols": 9.5, "rows": 6, "square_mm": 25},
        {"type": "charuco", "squares_x": 100000, "squares_y": 5, "square_mm": 40, "marker_mm": 30},
        {"type": "charuco", "squares_x": 7, "squares_y": 5, "square_mm": 40, "marker_mm": 50},
        {"type": "chessboard", "rows": 6, "square_mm": 25},
    ],
)
def test_bad_board_is_refused_and_stores_nothing(client, headers, board):
    r = client.post(
        "/api/calibration/sessions",
        json={"kind": "intrinsic", "board": board},
        headers=headers["engineer"],
    )
    assert r.status_code == 422 and r.json()["error"] == "validation_error", r.text
    assert client.get("/api/calibration/sessions", headers=headers["viewer"]).json()["count"] == 0


@pytest.mark.parametrize(
    "q",
    [
        [1e308, 1.2, -1.4, -0.5, 0.0],
        [math.nan, 1.2, -1.4, -0.5, 0.0],
        [True, 1.2, -1.4, -0.5, 0.0],
        [[0.0, 1.2, -1.4, -0.5, 0.0], [0.0, 1.2, -1.4, -0.5, math.inf]],
    ],
)
def test_core_fk_refuses_bad_joints(q):
    with pytest.raises(ValueError, match="q must"):
        fk(q)


def test_core_ik_refuses_bad_roll_and_position():
    pose = (0.8, 0.0, 1.0, 0.0, -1.0)
    with pytest.raises(ValueError, match="roll must"):
        ik(pose, roll=1e308)
    with pytest.raises(ValueError, match="roll must"):
        ik(pose, roll=True)
    with pytest.raises(ValueError, match="within 5 m"):
        ik((1e308, 0.0, 1.0, 0.0, -1.0))
    assert ASEA.within_limits(ik(pose, roll=0.3))


def test_core_board_constructors_are_bounded():
    with pytest.raises(ValueError, match=r"cols must be an integer in \[3, 100\]"):
        Chessboard(100000, 100000, 0.025)
    with pytest.raises(ValueError, match="cols must be an integer"):
        Chessboard(True, 6, 0.025)
    with pytest.raises(ValueError, match="square_m must be a length"):
        Chessboard(9, 6, 1e308)
    with pytest.raises(ValueError, match="squares_x must be an integer"):
        CharucoBoard(100000, 5, 0.04, 0.03)
