"""Two cells (two runtimes with different VISIONCELL_CELL_NAME) on one PostgreSQL database:
each has its own cell row, sessions and active calibrations; users are shared by the plant."""

from __future__ import annotations

from fastapi.testclient import TestClient

from backend.app import create_app
from tests.utils.factories import make_settings, make_tokens

BOARD = {"type": "chessboard", "cols": 9, "rows": 6, "square_mm": 30}


def _calibrate(client, hdr, folder) -> int:
    r = client.post(
        "/api/calibration/sessions", json={"kind": "intrinsic", "board": BOARD}, headers=hdr
    )
    assert r.status_code == 201, r.text
    sid = r.json()["session"]["id"]
    files = [("images", (f.name, f.read_bytes(), "image/png")) for f in folder.files]
    r = client.post(f"/api/calibration/sessions/{sid}/samples", files=files, headers=hdr)
    assert r.status_code == 201, r.text
    r = client.post(
        f"/api/calibration/sessions/{sid}/solve?wait=true",
        json={"activate": True, "radial_only": True},
        headers=hdr,
    )
    assert r.status_code == 200, r.text
    return sid


def test_two_cells_keep_their_own_calibrations(tmp_path, postgres_url, synthetic_folder):
    a = make_settings(tmp_path / "a", database_url=postgres_url, cell_name="cell-a")
    b = make_settings(tmp_path / "b", database_url=postgres_url, cell_name="cell-b")
    tokens = make_tokens(a)  # users belong to the plant: one token works in both cells
    hdr = {"Authorization": f"Bearer {tokens['engineer']}"}
    with TestClient(create_app(a)) as ca, TestClient(create_app(b)) as cb:
        cells = ca.get("/api/cells", headers=hdr).json()
        assert {c["name"] for c in cells["data"]} == {"cell-a", "cell-b"}
        ids = {c["name"]: c["id"] for c in cells["data"]}
        assert ca.get("/api/status", headers=hdr).json()["cell"]["id"] == ids["cell-a"]
        assert cb.get("/api/status", headers=hdr).json()["cell"]["id"] == ids["cell-b"]

        sid_a = _calibrate(ca, hdr, synthetic_folder)
        active_a = ca.get("/api/calibration/active", headers=hdr).json()
        assert active_a["intrinsic"] is not None
        assert active_a["intrinsic"]["session_id"] == sid_a
        # Cell B sees none of it: no active calibration, no session, no history.
        assert cb.get("/api/calibration/active", headers=hdr).json()["intrinsic"] is None
        assert cb.get("/api/calibration/sessions", headers=hdr).json()["count"] == 0
        assert cb.get("/api/calibration/calibrations", headers=hdr).json()["count"] == 0

        sid_b = _calibrate(cb, hdr, synthetic_folder)
        active_b = cb.get("/api/calibration/active", headers=hdr).json()["intrinsic"]
        assert active_b["session_id"] == sid_b != sid_a
        # Activating in B left A's active calibration alone.
        again_a = ca.get("/api/calibration/active", headers=hdr).json()["intrinsic"]
        assert again_a["id"] == active_a["intrinsic"]["id"]
        sessions_a = ca.get("/api/calibration/sessions", headers=hdr).json()["data"]
        assert [s["id"] for s in sessions_a] == [sid_a]
        assert {s["cell_id"] for s in sessions_a} == {ids["cell-a"]}
        # Cell B may read A's calibration (the plant shares reading), not change it.
        cid_a = again_a["id"]
        assert cb.get(f"/api/calibration/calibrations/{cid_a}", headers=hdr).status_code == 200
        r = cb.post(f"/api/calibration/calibrations/{cid_a}/activate", headers=hdr)
        assert r.status_code == 409 and r.json()["error"] == "other_cell", r.text
        r = cb.post(f"/api/calibration/sessions/{sid_a}/solve?wait=true", headers=hdr)
        assert r.status_code == 409 and "belongs to cell id" in r.json()["detail"]
        assert (
            cb.get("/api/calibration/active", headers=hdr).json()["intrinsic"]["id"]
            == active_b["id"]
        )


def test_a_second_start_of_a_cell_reuses_its_row(tmp_path, postgres_url):
    a = make_settings(tmp_path, database_url=postgres_url, cell_name="line-3_cell-2")
    hdr = {"Authorization": f"Bearer {make_tokens(a)['viewer']}"}
    for _ in range(2):
        with TestClient(create_app(a)) as c:
            cells = c.get("/api/cells", headers=hdr).json()
            assert [x["name"] for x in cells["data"]] == ["line-3_cell-2"]
