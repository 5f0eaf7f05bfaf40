"""Calibration documents over REST and the CLI: export, import (checked, audited,
optionally activated), roles, and every refused value named."""

from __future__ import annotations

import copy
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from backend.app import create_app
from backend.calibration import NOMINAL_T_EE_CAM
from tests.utils.servers import run_uvicorn

BOARD = {"type": "chessboard", "cols": 9, "rows": 6, "square_mm": 30}
IMPORT = "/api/calibration/calibrations/import"
#: Bounds a hang only (a loaded machine is slow to start a command); never a speed claim.
HANG_S = 240.0

INTRINSIC = {
    "format": "visioncell-calibration",
    "version": 1,
    "kind": "intrinsic",
    "parameters": {
        "K": [[150.0, 0.0, 64.0], [0.0, 151.0, 63.5], [0.0, 0.0, 1.0]],
        "dist": [-0.1, 0.01, 0.0, 0.0, 0.0],
        "image_size": [128, 128],
    },
    "sample_count": 12,
    "rms_px": 0.25,
    "source": {"tool": "another cell"},
}
HAND_EYE = {
    "format": "visioncell-calibration",
    "version": 1,
    "kind": "hand_eye",
    "parameters": {"T_ee_cam": NOMINAL_T_EE_CAM.tolist()},
    "sample_count": 12,
}


def _export(client, headers, cid, role="viewer"):
    r = client.get(f"/api/calibration/calibrations/{cid}/export", headers=headers[role])
    assert r.status_code == 200, r.text
    return r.json()


def _solved_hand_eye(client, headers, synthetic_folder) -> tuple[int, int]:
    """A hand-eye session solved from the synthetic board views: (hand-eye id, intrinsic id)."""
    r = client.post("/api/calibration/sessions", json={"kind": "hand_eye", "board": BOARD},
                    headers=headers["engineer"])  # fmt: skip
    assert r.status_code == 201, r.text
    sid = r.json()["session"]["id"]
    files = [("images", (f.name, f.read_bytes(), "image/png")) for f in synthetic_folder.files]
    files.append(("poses", ("poses.txt", synthetic_folder.poses_file.read_bytes(), "text/plain")))
    r = client.post(f"/api/calibration/sessions/{sid}/samples", files=files,
                    headers=headers["engineer"])  # fmt: skip
    assert r.status_code == 201, r.text
    r = client.post(f"/api/calibration/sessions/{sid}/solve?wait=true",
                    json={"methods": ["park"]}, headers=headers["engineer"])  # fmt: skip
    assert r.status_code == 200, r.text
    result = r.json()["job"]["result"]
    return result["calibration_id"], result["intrinsic_calibration_id"]


def test_a_solved_calibration_round_trips_through_export_and_import(
    client, headers, synthetic_folder
):
    he_id, intr_id = _solved_hand_eye(client, headers, synthetic_folder)
    docs = {cid: _export(client, headers, cid) for cid in (intr_id, he_id)}
    he_doc = docs[he_id]
    assert he_doc["format"] == "visioncell-calibration" and he_doc["version"] == 1
    assert he_doc["kind"] == "hand_eye" and set(he_doc["parameters"]) == {
        "T_ee_cam", "K", "dist", "image_size"}  # fmt: skip
    assert he_doc["source"]["calibration_id"] == he_id
    assert he_doc["source"]["intrinsics_id"] == intr_id and he_doc["source"]["cell"]
    new = {}
    for cid, doc in docs.items():
        r = client.post(IMPORT, json=doc, headers=headers["engineer"])
        assert r.status_code == 201, r.text
        cal = r.json()["calibration"]
        assert cal["active"] is False and cal["session_id"] is None
        new[cid] = cal["id"]
    for cid, doc in docs.items():
        again = _export(client, headers, new[cid])
        # What the cell uses comes back exactly; the source says where it came from.
        for key in ("format", "version", "kind", "parameters", "sample_count", "rms_px"):
            assert again[key] == doc[key], key
        assert again["source"]["calibration_id"] == new[cid]
        assert again["source"]["imported_from"] == doc["source"]
    # An imported calibration has no solve to report, and says so.
    r = client.get(f"/api/calibration/calibrations/{new[he_id]}/report", headers=headers["viewer"])
    assert r.status_code == 404 and "imported" in r.json()["detail"], r.text
    # Activated at import, in one request: the active ones are the imported ones.
    r = client.post(IMPORT, json={**docs[intr_id], "activate": True, "reason": "from cell 1"},
                    headers=headers["engineer"])  # fmt: skip
    assert r.status_code == 201 and r.json()["calibration"]["active"] is True, r.text
    active_intr = r.json()["calibration"]["id"]
    r = client.post(IMPORT, json={**docs[he_id], "activate": True}, headers=headers["engineer"])
    assert r.status_code == 201, r.text
    active = client.get("/api/calibration/active", headers=headers["viewer"]).json()
    assert active["intrinsic"]["id"] == active_intr
    assert active["hand_eye"]["id"] == r.json()["calibration"]["id"]
    # Audited: the imports and the activations, by the engineer.
    trail = client.get("/api/audit?kind=calibration", headers=headers["engineer"]).json()["data"]
    imports = [e for e in trail if e["action"] == "import"]
    assert len(imports) == 4 and {e["actor"] for e in imports} == {"test-engineer"}, imports
    assert any(e["action"] == "activate" and e["entity_id"] == str(active_intr) for e in trail)
    by_id = {e["entity_id"]: e for e in imports}
    assert by_id[str(active_intr)]["reason"] == "from cell 1"
    assert by_id[str(active_intr)]["new"]["parameters"] == docs[intr_id]["parameters"]


def test_roles(client, headers):
    r = client.post(IMPORT, json=INTRINSIC, headers=headers["engineer"])
    assert r.status_code == 201, r.text
    cid = r.json()["calibration"]["id"]
    for role in ("operator", "viewer"):
        r = client.post(IMPORT, json=INTRINSIC, headers=headers[role])
        assert r.status_code == 403 and r.json()["error"] == "forbidden", r.text
    assert client.post(IMPORT, json=INTRINSIC).status_code == 401
    assert client.get(f"/api/calibration/calibrations/{cid}/export").status_code == 401
    assert _export(client, headers, cid, "viewer")["parameters"] == INTRINSIC["parameters"]
    r = client.get("/api/calibration/calibrations/999/export", headers=headers["viewer"])
    assert r.status_code == 404, r.text
    r = client.get("/api/calibration/calibrations?kind=intrinsic", headers=headers["viewer"])
    assert r.json()["count"] == 1


def _with(doc: dict, path: str, value: object) -> dict:
    """``doc`` with the value at ``path`` (``a.b.0.1``) set, or removed when ``value`` is ...."""
    out = copy.deepcopy(doc)
    *keys, last = path.split(".")
    node = out
    for k in keys:
        node = node[int(k)] if isinstance(node, list) else node[k]
    key = int(last) if isinstance(node, list) else last
    if value is ...:
        del node[key]
    else:
        node[key] = value
    return out


def _rot_x(deg: float) -> list[list[float]]:
    import numpy as np
    from scipy.spatial.transform import Rotation

    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("x", deg, degrees=True).as_matrix()
    return T.tolist()


BAD = [
    (INTRINSIC, "format", "opencv", "format: Input should be 'visioncell-calibration' (got 'opencv')"),
    (INTRINSIC, "version", 2, "version: Input should be 1 (got 2)"),
    (INTRINSIC, "kind", "stereo", "kind: Input should be 'intrinsic' or 'hand_eye'"),
    (INTRINSIC, "parameters.K", [[150.0, 0.0, 64.0], [0.0, 151.0, 63.5]], "parameters.K must be a 3x3"),
    (INTRINSIC, "parameters.K.0.0", 0.0, "fx (K[0][0]) must be in 1..1e+06 px, got 0.0"),
    (INTRINSIC, "parameters.K.1.1", 5e6, "fy (K[1][1]) must be in 1..1e+06 px"),
    (INTRINSIC, "parameters.K.0.2", 200.0, "cx (K[0][2]) must lie in the image (0..128), got 200.0"),
    (INTRINSIC, "parameters.K.1.2", -1.0, "cy (K[1][2]) must lie in the image (0..128)"),
    (INTRINSIC, "parameters.K.2.0", 0.5, "last row (0, 0, 1)"),
    (INTRINSIC, "parameters.K.0.1", "a", "parameters.K[0][1] must be a finite number"),
    (INTRINSIC, "parameters.dist", [0.1, 0.0, 0.0], "parameters.dist must be a list of 4, 5, 8, 12, 14"),
    (INTRINSIC, "parameters.dist.1", 5e3, "parameters.dist[1] must be a finite number within +-1000"),
    (INTRINSIC, "parameters.dist", [0.1, 0, 0, 0, 0, 0.2, 0, 0], "parameters.dist[5] is 0.2"),
    (INTRINSIC, "parameters.image_size", [128, 0], "parameters.image_size[1] must be a whole number"),
    (INTRINSIC, "parameters.image_size", [128.5, 128], "parameters.image_size[0] must be a whole"),
    (INTRINSIC, "parameters.image_size", [100000, 128], "in 1..65535"),
    (INTRINSIC, "parameters.image_size", ..., "parameters.image_size is missing"),
    (INTRINSIC, "parameters.T_ee_cam", NOMINAL_T_EE_CAM.tolist(), "parameters.T_ee_cam is not a parameter of a intrinsic"),
    (INTRINSIC, "sample_count", -1, "sample_count: Input should be greater than or equal to 0"),
    (INTRINSIC, "rms_px", -0.5, "rms_px: Input should be greater than or equal to 0"),
    (INTRINSIC, "source", "cell-2", "source: Input should be a valid dictionary"),
    (INTRINSIC, "colour", "blue", "colour: Extra inputs are not permitted"),
    (HAND_EYE, "parameters.T_ee_cam", ..., "parameters.T_ee_cam is missing"),
    (HAND_EYE, "parameters.T_ee_cam.0.0", 1.5, "no rotation matrix"),
    (HAND_EYE, "parameters.T_ee_cam", [[-1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 1.0, 0], [0, 0, 0, 1.0]], "det = -1.0000"),
    (HAND_EYE, "parameters.T_ee_cam.3.0", 0.2, "last row (0, 0, 0, 1)"),
    (HAND_EYE, "parameters.T_ee_cam.2.3", 2.5, "the camera is 2.500 m from the flange; at most 2 m"),
    (HAND_EYE, "parameters.T_ee_cam", _rot_x(30.0)[:3], "parameters.T_ee_cam must be a 4x4"),
    (HAND_EYE, "parameters.K", INTRINSIC["parameters"]["K"], "parameters.dist is missing"),
]  # fmt: skip


@pytest.mark.parametrize(("doc", "path", "value", "detail"), BAD,
                         ids=[f"{d['kind']}-{p}-{v!r:.20}" for d, p, v, _ in BAD])  # fmt: skip
def test_every_bad_value_is_refused_naming_it_and_nothing_is_stored(
    client, headers, doc, path, value, detail
):
    r = client.post(IMPORT, json={**_with(doc, path, value), "activate": True},
                    headers=headers["engineer"])  # fmt: skip
    assert r.status_code == 422, r.text
    body = r.json()
    assert set(body) == {"error", "detail"} and detail in body["detail"], body
    r = client.get("/api/calibration/calibrations", headers=headers["viewer"])
    assert r.json()["count"] == 0


def test_non_finite_numbers_in_the_json_are_refused(client, headers):
    text = json.dumps(INTRINSIC).replace("-0.1", "NaN")
    r = client.post(IMPORT, content=text, headers={**headers["engineer"],
                    "Content-Type": "application/json"})  # fmt: skip
    assert r.status_code == 422, r.text
    assert "parameters.dist[0] must be a finite number" in r.json()["detail"]


def test_a_valid_hand_eye_document_without_intrinsics_and_a_rotated_one(client, headers):
    for T in (NOMINAL_T_EE_CAM.tolist(), _rot_x(30.0)):
        r = client.post(IMPORT, json=_with(HAND_EYE, "parameters.T_ee_cam", T),
                        headers=headers["engineer"])  # fmt: skip
        assert r.status_code == 201, r.text
        assert r.json()["calibration"]["parameters"] == {"T_ee_cam": T, "intrinsics_id": None}


# -- the CLI, as a user runs it ------------------------------------------------------------


def _cli(*args: str, token: str) -> subprocess.CompletedProcess[str]:
    exe = Path(sys.executable).with_name("visioncell")
    env = {**os.environ, "VISIONCELL_TOKEN": token}
    return subprocess.run([str(exe), "calibrate", *args], env=env, capture_output=True,
                          text=True, timeout=HANG_S)  # fmt: skip


def test_cli_export_and_import(settings, tokens, tmp_path):
    doc = tmp_path / "intrinsics.json"
    doc.write_text(json.dumps(INTRINSIC))
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(_with(INTRINSIC, "parameters.K.0.2", 300.0)))
    with run_uvicorn(create_app(settings)) as srv:
        url = ("--url", srv.base)
        done = _cli("import", str(doc), "--activate", *url, token=tokens["engineer"])
        assert done.returncode == 0, done.stderr
        assert "imported calibration 1 (intrinsic, active)" in done.stdout
        out = tmp_path / "out.json"
        done = _cli("export", "1", "-o", str(out), *url, token=tokens["viewer"])
        assert done.returncode == 0, done.stderr
        again = json.loads(out.read_text())
        assert again["parameters"] == INTRINSIC["parameters"]
        assert again["source"]["imported_from"] == INTRINSIC["source"]
        done = _cli("export", "1", *url, token=tokens["viewer"])  # to standard output
        assert done.returncode == 0 and json.loads(done.stdout) == again, done.stderr
        # Refused by the cell: the role, an unknown id (exit 2, the API's detail).
        done = _cli("import", str(doc), *url, token=tokens["operator"])
        assert done.returncode == 2 and "HTTP 403" in done.stderr, done.stderr
        done = _cli("export", "77", *url, token=tokens["viewer"])
        assert done.returncode == 2 and "no calibration with id 77" in done.stderr, done.stderr
        # Checked before any request: a bad value, a file that is no document.
        notjson = tmp_path / "notes.json"
        notjson.write_text("K = 150")
        for path, message in (
            (bad, "bad.json: parameters.K: cx (K[0][2]) must lie in the image (0..128), got 300.0"),
            (tmp_path / "missing.json", "is not a file"),
            (settings.var_dir, "is not a file"),
            (notjson, "is not a JSON calibration document"),
        ):
            done = _cli("import", str(path), *url, token=tokens["engineer"])
            assert done.returncode == 2, done.stderr
            assert message in done.stderr and "Traceback" not in done.stderr, done.stderr
        done = _cli("export", "0", *url, token=tokens["viewer"])
        assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
