"""``visioncell calibrate``, run as a real process."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from tests.utils.calibration import TRUE_T_EE_CAM, rotation_error_deg, translation_error_mm


def _invoke(*args: str):
    """In-process run (for the quick error cases); ``_run`` starts a real process."""
    from typer.testing import CliRunner

    from backend.cli import app

    return CliRunner().invoke(app, ["calibrate", *args])


def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "backend.cli", "calibrate", *args],
        capture_output=True,
        text=True,
        env={**os.environ, "COLUMNS": "120"},
        timeout=120,
    )


def test_intrinsics_report(synthetic_folder, tmp_path):
    save = tmp_path / "cam.json"
    png = tmp_path / "report.png"
    r = _run(
        "intrinsics",
        "--images",
        str(synthetic_folder.folder),
        "--board",
        "9x6",
        "--square",
        "30",
        "--save",
        str(save),
        "--report",
        str(png),
    )
    assert r.returncode == 0, r.stderr
    out = r.stdout
    assert "chessboard 9x6, 30 mm squares, 9 images" in out
    assert "Intrinsics (k1, k2, p1, p2): RMS 0.0" in out and "8 images used, 1 rejected" in out
    assert "view_08.png" in out and "no 9x6 chessboard found" in out
    for name in ("fx (px)", "fy (px)", "cx (px)", "cy (px)", "k1", "k2", "p1", "p2"):
        assert name in out
    saved = json.loads(save.read_text())
    assert saved["board"]["square_m"] == pytest.approx(0.03) and saved["K"][0][0] == pytest.approx(
        610, abs=3
    )
    assert png.read_bytes()[:4] == b"\x89PNG"


def test_intrinsics_json_is_the_last_line(synthetic_folder):
    r = _run(
        "intrinsics",
        "--images",
        str(synthetic_folder.folder),
        "--board",
        "9x6",
        "--square",
        "30mm",
        "--radial-only",
        "--json",
    )
    assert r.returncode == 0, r.stderr
    result = json.loads(r.stdout.strip().splitlines()[-1])
    assert result["options"]["radial_only"] is True and result["dist"][2:4] == [0.0, 0.0]
    assert len(result["views"]) == 8 and result["rejected"][0]["name"] == "view_08.png"


def test_hand_eye_report(synthetic_folder):
    r = _run(
        "hand-eye",
        "--images",
        str(synthetic_folder.folder),
        "--poses",
        str(synthetic_folder.poses_file),
        "--board",
        "9x6",
        "--square",
        "0.03m",
        "--json",
    )
    assert r.returncode == 0, r.stderr
    result = json.loads(r.stdout.strip().splitlines()[-1])
    X = np.array(result["hand_eye"]["T_ee_cam"])
    assert (
        translation_error_mm(X, TRUE_T_EE_CAM) < 1.0 and rotation_error_deg(X, TRUE_T_EE_CAM) < 0.2
    )
    r = _run(
        "hand-eye",
        "--images",
        str(synthetic_folder.folder),
        "--poses",
        str(synthetic_folder.poses_file),
        "--board",
        "9x6",
        "--square",
        "30mm",
        "--method",
        "park,tsai",
    )
    assert r.returncode == 0, r.stderr
    out = r.stdout
    assert "Hand-eye solvers" in out and "park" in out and "daniilidis" not in out
    assert "consistency of the board pose in the base frame: RMS" in out
    assert "T_ee_cam: t = (40." in out and "view_08.png" in out


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--board", "9by6", "--square", "25mm"], "board must look like 9x6, got '9by6'"),
        (
            ["--board", "9x6", "--square", "25in"],
            "square must be a positive length like 25mm or 0.025m, got '25in'",
        ),
    ],
)
def test_bad_values_are_named(synthetic_folder, args, message):
    r = _invoke("intrinsics", "--images", str(synthetic_folder.folder), *args)
    assert r.exit_code == 2 and message in r.stderr


def test_missing_folder_and_mismatched_poses(synthetic_folder, tmp_path):
    r = _run(
        "intrinsics", "--images", str(tmp_path / "nowhere"), "--board", "9x6", "--square", "25mm"
    )
    assert r.returncode == 2 and "images must be a folder, got" in r.stderr
    short = tmp_path / "short.txt"
    short.write_text("\n".join(synthetic_folder.poses_file.read_text().splitlines()[:3]))
    r = _run(
        "hand-eye",
        "--images",
        str(synthetic_folder.folder),
        "--poses",
        str(short),
        "--board",
        "9x6",
        "--square",
        "30mm",
    )
    assert r.returncode == 2
    assert "poses: short.txt has 3 poses but" in r.stderr and "holds 9 images" in r.stderr
    r = _run(
        "hand-eye",
        "--images",
        str(synthetic_folder.folder),
        "--poses",
        str(synthetic_folder.poses_file),
        "--board",
        "9x6",
        "--square",
        "30mm",
        "--method",
        "magic",
    )
    assert r.returncode == 2 and "methods must be a non-empty subset of" in r.stderr


def test_opencv_left_through_the_cli(data_dir):
    folder = data_dir / "calibration" / "opencv-left"
    if not folder.is_dir():
        pytest.skip(f"{folder} is absent")
    r = _run("intrinsics", "--images", str(folder), "--board", "9x6", "--square", "25mm", "--json")
    assert r.returncode == 0, r.stderr
    result = json.loads(r.stdout.strip().splitlines()[-1])
    assert result["rms_px"] <= 0.25 and abs(result["K"][0][0] / 535.9 - 1) <= 0.01


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--board", "dots"], "board must be chessboard or charuco, got 'dots'"),
        (["--poses", "2"], "poses must be in [3, 60], got 2"),
        (["--time-scale", "0"], "time-scale must be in [0.1, 100], got 0.0"),
    ],
)
def test_auto_bad_arguments(args, message):
    # The full in-process run is covered through the API (tests/backend/test_calibration_auto.py)
    # and by `python -m benchmarks.calibration_sim`.
    r = _invoke("auto", *args)
    assert r.exit_code == 2 and message in r.stderr
