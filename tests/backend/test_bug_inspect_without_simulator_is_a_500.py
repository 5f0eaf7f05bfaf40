"""A cell without the simulator (ideal driver, folder camera, no camera calibration) inspects.

``POST /api/inspections`` answered 500 (``'Frame' object is not callable``: the context read
the latest frame as a method) on every cell without the simulator until a calibration was
activated, and ``POST /api/inspection/run`` failed the same way.  Now the cell uses nominal
intrinsics and says so; recognition works, the pose and the pick end with the reason, and
sorting says this cell has no bins.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from tests.utils.factories import make_settings, make_tokens, migrate
from tests.utils.recorded import coil_dir, coil_file, link_sequence, upload_views, wait_job


@pytest.fixture
def cell(tmp_path, data_dir) -> Iterator[tuple[TestClient, dict[str, dict[str, str]]]]:
    coil = coil_dir(data_dir)
    # The camera shows one real image: object 1 at 25 degrees (a view not trained).
    folder = link_sequence(tmp_path / "camera", [coil_file(coil, 1, 5)])
    settings = make_settings(tmp_path, camera_folder=folder, data_dir=data_dir)
    migrate(settings)
    tokens = make_tokens(settings)
    headers = {role: {"Authorization": f"Bearer {tok}"} for role, tok in tokens.items()}
    with TestClient(create_app(settings)) as client:
        for obj in (1, 2):
            r = client.post("/api/models", json={"name": f"obj{obj}", "kind": "2d", "threshold": 0.15},
                            headers=headers["engineer"])  # fmt: skip
            assert r.status_code == 201, r.text
            files = [coil_file(coil, obj, k) for k in range(0, 72, 6)]
            r = upload_views(client, headers["engineer"], r.json()["id"], files)
            assert r.status_code == 201, r.text
        yield client, headers


def _inspect(client: TestClient, headers: dict[str, dict[str, str]], **body: object) -> dict:
    r = client.post("/api/inspections", json={"policy": "top-only", **body},
                    headers=headers["operator"])  # fmt: skip
    assert r.status_code == 202, r.text
    job = wait_job(client, headers["viewer"], r.json()["job"]["id"])
    assert job["state"] == "done", job
    iid = job["result"]["inspection_id"]
    r = client.get(f"/api/inspections/{iid}", headers=headers["viewer"])
    assert r.status_code == 200, r.text
    return r.json()


def test_inspection_without_simulator_or_calibration_recognises_and_says_why_no_pose(cell):
    client, headers = cell
    row = _inspect(client, headers)
    assert row["decision"] == "recognized" and row["model"] == "obj1", (
        row["reason"],
        row["scores"],
    )
    assert "nominal intrinsics (uncalibrated)" in row["reason"]
    assert "whole image" in row["reason"]
    assert row["pose"] is None
    assert "pose not computed: needs an active camera calibration" in row["reason"]
    assert (
        row["pick"]["ok"] is False and "needs an active camera calibration" in row["pick"]["reason"]
    )


def test_sorting_without_bins_says_so_and_a_run_inspects(cell):
    client, headers = cell
    row = _inspect(client, headers, sort=True)
    assert row["decision"] == "recognized", row
    assert row["pick"]["sorted"] is True and row["pick"]["ok"] is False
    assert "sorting is not available: this cell has no bins" in row["pick"]["reason"]
    r = client.post("/api/inspection/run", json={"count": 2, "policy": "top-only"},
                    headers=headers["operator"])  # fmt: skip
    assert r.status_code == 202, r.text
    job = wait_job(client, headers["viewer"], r.json()["job"]["id"])
    assert job["state"] == "done", job
    assert job["result"]["inspected"] == 2
    assert job["result"]["decisions"] == {"recognized": 2}
