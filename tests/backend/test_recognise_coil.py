"""On the user's path with real images: a cell (ideal driver, folder camera, no simulator)
served by uvicorn, tokens printed by ``visioncell user add``, COIL-20 objects 1-10 uploaded
through REST at 10 degree spacing, the threshold chosen by the product itself, then the
untrained views of 1-10 and views of 11-15 recognised through the endpoint (subsampled:
the figures over every view are the benchmark's, ``benchmarks/recorded.py``), and the CLI
over a folder as a subprocess."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import httpx
import pytest

from backend.app import create_app
from benchmarks.recognition_data import coil_folder
from benchmarks.recorded import Plan, score, train, wait_for_threshold
from tests.utils.factories import TEST_SECRET, make_settings, migrate
from tests.utils.servers import run_uvicorn

#: Objects 1-10 trained at 10 degree spacing; every 6th untrained view of 1-10 and every
#: 12th view of 11-15 queried.
PLAN = Plan(train_step=2, known_step=6, unknown_step=12)
#: Bounds a hang only (uploads and the threshold take tens of seconds on a loaded machine).
TIMEOUT_S = 1200.0


def _cli(args: list[str], settings, **env: str) -> subprocess.CompletedProcess[str]:
    full = {**os.environ, "VISIONCELL_DATABASE_URL": settings.database_url,
            "VISIONCELL_SECRET_KEY": TEST_SECRET, **env}  # fmt: skip
    return subprocess.run([sys.executable, "-m", "backend.cli", *args], capture_output=True,
                          text=True, env=full, timeout=TIMEOUT_S)  # fmt: skip


def _token(settings, name: str, role: str) -> str:
    r = _cli(["user", "add", name, "--role", role], settings)
    assert r.returncode == 0, r.stderr
    return r.stdout.strip().splitlines()[-1]


@pytest.fixture(scope="module")
def coil_cell(data_dir, tmp_path_factory):
    try:
        folder = coil_folder(data_dir)
    except FileNotFoundError as exc:
        pytest.skip(str(exc))
    tmp = tmp_path_factory.mktemp("coil")
    settings = make_settings(tmp, camera_folder=folder, data_dir=data_dir,
                             threshold_follow=True, threshold_quiet_s=1.0)  # fmt: skip
    migrate(settings)
    engineer = _token(settings, "erin", "engineer")
    viewer = _token(settings, "vic", "viewer")
    with run_uvicorn(create_app(settings)) as srv:
        client = httpx.Client(base_url=srv.base, timeout=TIMEOUT_S,
                              headers={"Authorization": f"Bearer {engineer}"})  # fmt: skip
        train(client, folder, PLAN)  # objects 1-10, views at 10 degree spacing
        status = wait_for_threshold(client, TIMEOUT_S)
        yield srv, client, viewer, folder, status, settings
        client.close()


def test_the_product_chooses_the_threshold_and_recognises_coil(coil_cell):
    srv, _client, viewer, folder, status, _settings = coil_cell
    chosen = status["settings"]
    assert chosen["chosen_by"] == "auto" and chosen["detail"]["views"] == 360
    assert 0.03 <= chosen["global_threshold"] < 0.5
    # One recomputation for the ten uploads (coalesced), perhaps one more if an upload
    # came after the quiet period on a loaded machine; never one per upload.
    assert 1 <= status["runs"] < 10
    rows = []
    queries = PLAN.known_queries() + PLAN.unknown_queries()
    for start in range(0, len(queries), 8):
        part = queries[start : start + 8]
        files = [("images", (f"obj{o}__{k}.png", (folder / f"obj{o}__{k}.png").read_bytes(),
                             "image/png")) for o, k in part]  # fmt: skip
        r = httpx.post(f"{srv.base}/api/recognition/recognise", files=files, timeout=TIMEOUT_S,
                       headers={"Authorization": f"Bearer {viewer}"})  # fmt: skip
        assert r.status_code == 200, r.text
        for (o, _k), res in zip(part, r.json()["data"], strict=True):
            rows.append((f"obj{o}" if o <= 10 else None, res))
    got = score(rows)
    assert got["known"] == 60 and got["unknown"] == 30
    assert got["top1"] >= 0.95, got
    assert got["false_rejects"] <= 0.1, got
    assert got["false_accept_count"] <= 2, got
    assert got["misrecognised"] == 0, got


def test_the_cli_recognises_a_folder(coil_cell, tmp_path):
    srv, _client, viewer, folder, _status, settings = coil_cell
    shots = tmp_path / "shots"
    shots.mkdir()
    names = ["obj3__5.png", "obj7__33.png", "obj12__0.png", "obj14__40.png"]
    for n in names:
        shutil.copy(folder / n, shots / n)
    (shots / "notes.txt").write_text("not an image: left out of a folder")
    r = _cli(["recognise", str(shots), "--url", srv.base, "--token", viewer, "--json"], settings)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout.strip().splitlines()[-1])
    by_name = {d["name"]: d for d in out["data"]}
    assert sorted(by_name) == sorted(names)
    assert by_name["obj3__5.png"]["model"] == "obj3"
    assert by_name["obj7__33.png"]["model"] == "obj7"
    assert by_name["obj12__0.png"]["decision"] != "recognized"
    assert "recognising" in r.stderr  # the progress bar over the folder
    # CSV, with a file the cell refuses reported on its own row.
    (shots / "broken.png").write_bytes(b"\x89PNG\r\n\x1a\n" + b"\0" * 40)
    r = _cli(["recognise", str(shots), "--url", srv.base, "--token", viewer, "--csv"], settings)
    assert r.returncode == 0, r.stderr
    lines = r.stdout.strip().splitlines()
    assert lines[0].startswith("name,decision,model,score,threshold")
    broken = next(x for x in lines if x.startswith("broken.png"))
    assert ",error," in broken
    assert sum(1 for x in lines[1:] if ",recognized,obj" in x) == 2
    # Storing needs an operator: the viewer's token is refused with the reason.
    r = _cli(["recognise", str(shots / "obj3__5.png"), "--url", srv.base, "--token", viewer,
              "--store"], settings)  # fmt: skip
    assert r.returncode == 2 and "operator" in r.stderr
    # Bad paths are refused before anything is sent.
    r = _cli(["recognise", str(Path(shots) / "missing.png"), "--url", srv.base, "--token", viewer],
             settings)  # fmt: skip
    assert r.returncode == 2 and "does not exist" in r.stderr


#: Stored through the endpoint and the CLI: objects 1-10 at untrained angles, and 11-15.
STORED = [(1, 3), (4, 41), (9, 69), (11, 10), (13, 50), (15, 7)]


def _check_stored_row(client: httpx.Client, answer: dict, obj: int) -> None:
    """The inspection row ``store=true`` made of one answer: what the answer said, kept."""
    r = client.get(f"/api/inspections/{answer['inspection_id']}")
    assert r.status_code == 200, r.text
    row = r.json()
    assert row["source"] == "upload" and row["policy"] == "image", row
    assert row["decision"] == answer["decision"] and row["model"] == answer["model"], row
    assert row["scores"] == {s["model"]: s["score"] for s in answer["scores"]}, row
    assert row["viewpoints_visited"] == [answer["viewpoint"]] == [1]
    assert answer["name"] in row["reason"]
    assert set(row["durations"]) == {"acquire", "features", "match", "decide"}
    if obj <= 10:
        assert row["decision"] == "recognized" and row["model"] == f"obj{obj}", row
        assert row["model_id"] is not None and row["score"] > answer["threshold"]
        image = row["pose"]["image"]
        assert (
            round(image["x_px"], 2) == answer["pose"]["x_px"]
            and image["view_id"] == answer["view_id"]
        )
    else:
        assert row["decision"] != "recognized" and row["model"] is None, row
    # The image with the matched outline drawn, as the cell's own inspections keep theirs.
    r = client.get(row["images"][0])
    assert r.status_code == 200 and r.content[:2] == b"\xff\xd8", r.headers


def test_stored_results_are_inspection_rows(coil_cell, tmp_path):
    srv, client, _viewer, folder, _status, settings = coil_cell
    operator = _token(settings, "olga", "operator")
    before = client.get("/api/inspections", params={"limit": 1}).json()["count"]
    files = [("images", (f"obj{o}__{k}.png", (folder / f"obj{o}__{k}.png").read_bytes(),
                         "image/png")) for o, k in STORED]  # fmt: skip
    r = httpx.post(f"{srv.base}/api/recognition/recognise", files=files, data={"store": "true"},
                   headers={"Authorization": f"Bearer {operator}"}, timeout=TIMEOUT_S)  # fmt: skip
    assert r.status_code == 200, r.text
    answers = r.json()["data"]
    assert len(answers) == len(STORED)
    for (o, _k), answer in zip(STORED, answers, strict=True):
        _check_stored_row(client, answer, o)
    # The CLI over a folder with --store, as a subprocess with the operator's token.
    shots = tmp_path / "stored"
    shots.mkdir()
    for o, k in STORED:
        shutil.copy(folder / f"obj{o}__{k}.png", shots / f"obj{o}__{k}.png")
    r = _cli(["recognise", str(shots), "--url", srv.base, "--token", operator, "--store",
              "--json"], settings)  # fmt: skip
    assert r.returncode == 0, r.stderr
    by_name = {d["name"]: d for d in json.loads(r.stdout.strip().splitlines()[-1])["data"]}
    assert sorted(by_name) == sorted(f"obj{o}__{k}.png" for o, k in STORED)
    for o, k in STORED:
        cli_answer = by_name[f"obj{o}__{k}.png"]
        _check_stored_row(client, cli_answer, o)
        rest = answers[STORED.index((o, k))]
        assert cli_answer["scores"] == rest["scores"], (cli_answer, rest)
    after = client.get("/api/inspections", params={"limit": 1}).json()["count"]
    assert after == before + 2 * len(STORED)
