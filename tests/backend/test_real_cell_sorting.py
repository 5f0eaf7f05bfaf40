"""Sorting on a real cell: its bins come from the layout file, not from the simulator.

``visioncell serve`` runs as a user starts it (ideal driver, folder camera of real COIL-20
images, ``VISIONCELL_CELL_LAYOUT`` naming a TOML layout with bins); the token it prints
signs in; an inspection with ``sort`` sorts the part into the bin the layout gives its
model: uncalibrated it says where the part would go and why it is not picked; with a camera
calibration imported and activated with the CLI the pick is planned and made into that
bin.  A layout without bins says so, naming the layout; a bad layout stops the start
naming the value.
"""

from __future__ import annotations

import json
import os
import re
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
from fastapi.testclient import TestClient
from pydantic import ValidationError

from backend.app import create_app
from backend.calibration import NOMINAL_T_EE_CAM
from tests.utils.factories import make_settings, make_tokens, migrate
from tests.utils.recorded import coil_dir, coil_file, link_sequence, upload_views, wait_job

#: Bounds a hang only (a loaded machine is slow to start a server); never a speed claim.
HANG_S = 240.0

LAYOUT = """
[station]
x_m = 0.8
y_m = 0.0
surface_z_m = 0.45

[[bins]]
name = "bin-one"
parts = ["obj1"]
drop_m = [0.31, 0.61, 0.30]

[[bins]]
name = "bin-two"
parts = ["obj2"]
drop_m = [-0.11, 0.85, 0.30]

[[bins]]
name = "reject"
reject = true
drop_m = [-0.53, -0.51, 0.30]
"""


def _camera(tmp_path: Path, data_dir: Path) -> tuple[Path, Path]:
    coil = coil_dir(data_dir)
    # The camera shows one real image: object 1 at 25 degrees (a view not trained).
    return coil, link_sequence(tmp_path / "camera", [coil_file(coil, 1, 5)])


def _teach(client: object, eng: dict[str, str], coil: Path) -> None:
    for obj in (1, 2):
        r = client.post("/api/models", json={"name": f"obj{obj}", "kind": "2d", "threshold": 0.15},
                        headers=eng)  # type: ignore[attr-defined]  # fmt: skip
        assert r.status_code == 201, r.text
        files = [coil_file(coil, obj, k) for k in range(0, 72, 6)]
        r = upload_views(client, eng, r.json()["id"], files)
        assert r.status_code == 201, r.text


def _inspect_sorted(client: object, headers: dict[str, str]) -> dict:
    r = client.post("/api/inspections", json={"policy": "top-only", "sort": True},
                    headers=headers)  # type: ignore[attr-defined]  # fmt: skip
    assert r.status_code == 202, r.text
    job = wait_job(client, headers, r.json()["job"]["id"])
    assert job["state"] == "done", job
    r = client.get(f"/api/inspections/{job['result']['inspection_id']}", headers=headers)  # type: ignore[attr-defined]
    assert r.status_code == 200, r.text
    return r.json()


def _import_calibrations(tmp_path: Path, url: str, token: str) -> None:
    """Import and activate two calibrations with the CLI as a user would: intrinsics of the
    128 x 128 images and the camera's mounting.  They stand in for calibrations solved on
    another cell or by another tool (this camera, a folder of object photos, shows no
    board)."""
    docs = {
        "intrinsics.json": {"kind": "intrinsic", "sample_count": 12, "parameters": {
            "K": [[150.0, 0, 64.0], [0, 150.0, 64.0], [0, 0, 1]], "dist": [0.0] * 5,
            "image_size": [128, 128]}},
        "hand-eye.json": {"kind": "hand_eye", "sample_count": 12,
                          "parameters": {"T_ee_cam": NOMINAL_T_EE_CAM.tolist()}},
    }  # fmt: skip
    exe = Path(sys.executable).with_name("visioncell")
    for name, doc in docs.items():
        path = tmp_path / name
        path.write_text(json.dumps({"format": "visioncell-calibration", "version": 1, **doc}))
        done = subprocess.run(
            [str(exe), "calibrate", "import", str(path), "--activate", "--url", url,
             "--token", token], capture_output=True, text=True, timeout=HANG_S,
        )  # fmt: skip
        assert done.returncode == 0, done.stderr
        assert f"({doc['kind']}, active)" in done.stdout, done.stdout


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


@pytest.fixture
def served(tmp_path: Path, data_dir: Path) -> Iterator[tuple[httpx.Client, dict[str, str], str]]:
    coil, folder = _camera(tmp_path, data_dir)
    layout = tmp_path / "cell.toml"
    layout.write_text(LAYOUT)
    settings = make_settings(tmp_path, camera_folder=folder, data_dir=data_dir)
    migrate(settings)
    port = _free_port()
    env = {
        **os.environ,
        "VISIONCELL_DATABASE_URL": settings.database_url,
        "VISIONCELL_HTTP_HOST": "127.0.0.1",
        "VISIONCELL_HTTP_PORT": str(port),
        "VISIONCELL_VIEW3D_ENABLED": "false",
        "VISIONCELL_DRIVER": "ideal",
        "VISIONCELL_CAMERA": "folder",
        "VISIONCELL_CAMERA_FOLDER": str(folder),
        "VISIONCELL_CELL_LAYOUT": str(layout),
        "VISIONCELL_DATA_DIR": str(data_dir),
        "VISIONCELL_VAR_DIR": str(settings.var_dir),
        "VISIONCELL_SECRET_KEY": settings.secret_key.get_secret_value(),
    }
    out = tmp_path / "serve.log"
    exe = Path(sys.executable).with_name("visioncell")
    with open(out, "ab") as log:
        proc = subprocess.Popen([str(exe), "serve"], env=env, stdout=log, stderr=log)
    try:
        deadline = time.monotonic() + HANG_S
        with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=60.0) as client:
            while True:
                assert proc.poll() is None, out.read_text()[-2000:]
                assert time.monotonic() < deadline, "serve never answered /api/health"
                try:
                    if client.get("/api/health").status_code == 200:
                        break
                except httpx.HTTPError:
                    pass
                time.sleep(0.1)
            tokens = re.findall(r"^\s+(vc_\S+)\s*$", out.read_text(), flags=re.M)
            assert tokens, out.read_text()[-2000:]
            eng = {"Authorization": f"Bearer {tokens[-1]}"}
            _teach(client, eng, coil)
            yield client, eng, tokens[-1]
    finally:
        proc.terminate()
        try:
            proc.wait(60)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(60)


def test_a_real_cell_plans_the_pick_into_the_bin_of_its_layout(served, tmp_path):
    client, eng, token = served
    row = _inspect_sorted(client, eng)
    assert row["decision"] == "recognized" and row["model"] == "obj1", row["reason"]
    pick = row["pick"]
    assert pick["sorted"] is True and pick["bin"] == "bin-one" and pick["reject"] is False, pick
    # Uncalibrated, the part is not picked: the result says where it would go and why not.
    assert pick["ok"] is False and "needs an active camera calibration" in pick["reason"]
    assert "it would go to bin 'bin-one'" in pick["reason"]
    assert "no bins" not in pick["reason"]
    # The fixed station is no belt the cell can read or start.
    r = client.get("/api/belt", headers=eng)
    assert r.status_code == 200 and r.json()["belt"] is None, r.text
    r = client.post("/api/belt", json={"running": True}, headers=eng)
    assert r.status_code == 409 and r.json()["error"] == "conflict", r.text
    # Calibrated (imported and activated with the CLI): the part is picked (a guarded
    # descent: imported views give no pose) and dropped into its bin by the ideal driver.
    _import_calibrations(tmp_path, str(client.base_url), token)
    active = client.get("/api/calibration/active", headers=eng).json()
    assert active["intrinsic"]["parameters"]["K"][0][0] == 150.0, active
    assert active["hand_eye"]["parameters"]["T_ee_cam"] == NOMINAL_T_EE_CAM.tolist(), active
    row = _inspect_sorted(client, eng)
    assert row["decision"] == "recognized" and row["model"] == "obj1", row["reason"]
    assert "uncalibrated" not in row["reason"], row["reason"]
    pick = row["pick"]
    assert pick["sorted"] is True and pick["bin"] == "bin-one" and pick["reject"] is False, pick
    assert pick["search"] is True and pick["ok"] is True, pick


def _layout_cell(
    tmp_path: Path, data_dir: Path, layout_text: str
) -> tuple[TestClient, dict[str, dict[str, str]], Path, Path]:
    coil, folder = _camera(tmp_path, data_dir)
    layout = tmp_path / "cell.json"
    layout.write_text(layout_text)
    settings = make_settings(tmp_path, camera_folder=folder, data_dir=data_dir,
                             cell_layout=layout)  # fmt: skip
    migrate(settings)
    tokens = make_tokens(settings)
    headers = {role: {"Authorization": f"Bearer {tok}"} for role, tok in tokens.items()}
    return TestClient(create_app(settings)), headers, coil, layout


def test_a_layout_without_bins_says_sorting_needs_them(tmp_path, data_dir):
    client, headers, coil, layout = _layout_cell(
        tmp_path, data_dir, '{"station": {"x_m": 0.8, "y_m": 0.0, "surface_z_m": 0.45}}'
    )
    with client:
        _teach(client, headers["engineer"], coil)
        row = _inspect_sorted(client, headers["operator"])
    assert row["decision"] == "recognized", row
    reason = row["pick"]["reason"]
    assert row["pick"]["ok"] is False and "bin" not in row["pick"], row["pick"]
    assert "sorting is not available: this cell has no bins" in reason
    assert str(layout) in reason and "VISIONCELL_CELL_LAYOUT" in reason


def test_a_bad_layout_stops_the_start_naming_the_value(tmp_path):
    bad = tmp_path / "cell.toml"
    bad.write_text(LAYOUT.replace("[0.31, 0.61, 0.30]", "[0.31, nan, 0.30]"))
    with pytest.raises(
        ValidationError, match=r"bins\[0\] \('bin-one'\)\.drop_m\[1\] must be a finite"
    ):
        make_settings(tmp_path, driver="ideal", camera="folder", cell_layout=bad)
    with pytest.raises(ValidationError, match=r"the simulated cell .* has its own layout"):
        make_settings(tmp_path, driver="sim", cell_layout=bad)
    # As a user meets it: the command stops at once with the message.
    env = {**os.environ, "VISIONCELL_DRIVER": "ideal", "VISIONCELL_CAMERA": "folder",
           "VISIONCELL_CELL_LAYOUT": str(bad), "VISIONCELL_VAR_DIR": str(tmp_path / "var")}  # fmt: skip
    exe = Path(sys.executable).with_name("visioncell")
    done = subprocess.run([str(exe), "serve"], env=env, capture_output=True, text=True,
                          timeout=HANG_S)  # fmt: skip
    assert done.returncode != 0
    assert "VISIONCELL_CELL_LAYOUT" in done.stderr + done.stdout
    assert "drop_m[1] must be a finite number, got nan" in done.stderr + done.stdout
