"""A recorded cell: models imported from COIL-20 folders through the CLI, the threshold
chosen by the product itself when the cell starts, then a recorded sequence of known and
unknown images replayed by the folder camera (one image per look, in the order of its
``order.txt``) through REST inspections with the ideal driver; every stored row is checked
against the threshold in force, the replay gives the same decisions the second time round,
and a teach is refused with a pointer to the import."""

from __future__ import annotations

import os
import subprocess
import sys
import time

from fastapi.testclient import TestClient

from backend.app import create_app
from tests.utils.factories import TEST_SECRET, make_settings, make_tokens, migrate
from tests.utils.recorded import JOB_WAIT_S, coil_dir, coil_file, wait_job

#: Trained: objects 1-3, every 10 degrees.  The recording: untrained views of them
#: (5 degrees off a trained one) and views of objects 11 and 12, never trained.
KNOWN = (1, 2, 3)
SEQUENCE = [(1, 7), (11, 0), (2, 33), (12, 18), (3, 59), (1, 13)]


def _import(settings, name: str, folder) -> None:
    env = {
        **os.environ,
        "VISIONCELL_DATABASE_URL": settings.database_url,
        "VISIONCELL_SECRET_KEY": TEST_SECRET,
    }
    r = subprocess.run(
        [sys.executable, "-m", "backend.cli", "models", "import", name, str(folder), "--kind", "2d"],
        capture_output=True, text=True, env=env, timeout=600,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert f"imported 36 views into model {name!r}" in r.stdout


def _automatic_threshold(client, headers) -> dict:
    """The threshold the product chose by itself (its keeper recomputes it when the cell
    starts with trained views): polls its status; the bound only catches a hang."""
    deadline = time.monotonic() + JOB_WAIT_S
    while True:
        s = client.get("/api/recognition/threshold", headers=headers).json()
        if s["state"] == "idle" and s["settings"]["chosen_by"] == "auto":
            return s["settings"]
        assert time.monotonic() < deadline, s
        time.sleep(0.2)


def test_recorded_sequence_replays_to_the_same_decisions(tmp_path, data_dir):
    coil = coil_dir(data_dir)
    camera = tmp_path / "recording"
    camera.mkdir()
    names = []
    for i, (obj, k) in enumerate(SEQUENCE):
        name = f"shot{i}_obj{obj}_{k}.png"
        (camera / name).symlink_to(coil_file(coil, obj, k))
        names.append(name)
    # The stated order is the order file's, not the names' (a name order would differ).
    names = names[::-1]
    expected = SEQUENCE[::-1]
    (camera / "order.txt").write_text("# recorded top views\n" + "\n".join(names) + "\n")
    settings = make_settings(tmp_path, camera_folder=camera, camera_replay="look",
                             camera_order="manifest", data_dir=data_dir, threshold_follow=True,
                             threshold_quiet_s=0.5)  # fmt: skip
    migrate(settings)
    for obj in KNOWN:
        views = tmp_path / f"import{obj}"
        views.mkdir()
        for k in range(0, 72, 2):
            (views / f"obj{obj}_{k:02d}_top.png").symlink_to(coil_file(coil, obj, k))
        _import(settings, f"obj{obj}", views)
    tokens = make_tokens(settings)
    h = {role: {"Authorization": f"Bearer {tok}"} for role, tok in tokens.items()}
    with TestClient(create_app(settings)) as client:
        chosen = _automatic_threshold(client, h["viewer"])
        assert chosen["detail"]["views"] == 36 * len(KNOWN), chosen
        threshold = chosen["global_threshold"]
        assert 0.0 < threshold < 0.5, chosen
        models = {
            m["name"]: m["id"]
            for m in client.get("/api/models", headers=h["viewer"]).json()["data"]
        }
        assert sorted(models) == ["obj1", "obj2", "obj3"]
        r = client.post(f"/api/models/{models['obj1']}/teach", json={}, headers=h["engineer"])
        assert r.status_code == 409, r.text
        assert "visioncell models import" in r.json()["detail"]

        rows = []
        for _ in range(2):  # the recording twice round: the same decisions
            for _ in expected:
                r = client.post("/api/inspections", json={"policy": "top-only"},
                                headers=h["operator"])  # fmt: skip
                assert r.status_code == 202, r.text
                job = wait_job(client, h["viewer"], r.json()["job"]["id"])
                assert job["state"] == "done", job
                r = client.get(f"/api/inspections/{job['result']['inspection_id']}",
                               headers=h["viewer"])  # fmt: skip
                assert r.status_code == 200, r.text
                rows.append(r.json())
    assert len(rows) == 2 * len(expected)
    got = [(r["decision"], r["model"], r["score"]) for r in rows]
    for row, (obj, _k) in zip(rows, expected * 2, strict=True):
        best = max(row["scores"].values())
        if obj in KNOWN:
            assert row["decision"] == "recognized" and row["model"] == f"obj{obj}", (got, expected)
            assert row["model_id"] == models[f"obj{obj}"]
            # The row's score and its model's entry (rounded to 4 places) are the best.
            assert row["scores"][f"obj{obj}"] == best == round(row["score"], 4), row
            assert row["score"] > threshold, (row, threshold)
        else:
            assert row["decision"] == "unknown" and row["model"] is None, (got, expected)
            assert best <= threshold, (row, threshold)
        assert row["viewpoints_visited"] == [1] and row["pose"] is None
        assert "whole image" in row["reason"] and "uncalibrated" in row["reason"]
        assert set(row["scores"]) == {"obj1", "obj2", "obj3"}
    first, second = rows[: len(expected)], rows[len(expected) :]
    assert [r["scores"] for r in first] == [r["scores"] for r in second]
