"""``visioncell models``: add, list, import (names and manifest), remove, bad input."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import cv2
import numpy as np

from backend.cli.models import parse_viewpoint
from tests.utils.factories import TEST_SECRET
from tests.utils.models import png_bytes, textured_rgb


def _run(args, tmp_path):
    env = {
        **os.environ,
        "VISIONCELL_DATABASE_URL": f"sqlite+aiosqlite:///{tmp_path / 'cli.db'}",
        "VISIONCELL_SECRET_KEY": TEST_SECRET,
    }
    return subprocess.run(
        [sys.executable, "-m", "backend.cli", "models", *args],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )


def test_viewpoints_from_file_names():
    assert parse_viewpoint("wheel_top.png") == 1
    assert parse_viewpoint("a-vp2-03.jpg") == 2
    assert parse_viewpoint("OUTER.png") == 3
    assert parse_viewpoint("v1_and_v2.png") is None
    assert parse_viewpoint("overview.png") is None


def test_add_import_list_remove(tmp_path):
    r = _run(["add", "gear", "--kind", "3d", "--part", "gearbox"], tmp_path)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip().splitlines()[-1].isdigit()
    folder = tmp_path / "views"
    folder.mkdir()
    (folder / "gear_top.png").write_bytes(png_bytes(textured_rgb(1)))
    (folder / "gear_vp2.png").write_bytes(png_bytes(textured_rgb(2)))
    mask = np.zeros((240, 320), np.uint8)
    mask[20:220, 20:300] = 255
    cv2.imwrite(str(folder / "gear_top_mask.png"), mask)
    r = _run(["import", "gear", str(folder)], tmp_path)
    assert r.returncode == 0, r.stderr
    assert "imported 2 views into model 'gear'" in r.stdout
    r = _run(["list"], tmp_path)
    assert r.returncode == 0 and "gearbox" in r.stdout and "2 (1/1/0)" in r.stdout

    other = tmp_path / "other"
    other.mkdir()
    (other / "a.png").write_bytes(png_bytes(textured_rgb(3)))
    (other / "manifest.json").write_text(
        json.dumps([{"file": "a.png", "viewpoint": 3, "yaw_rad": 0.5}])
    )
    r = _run(["import", "pipe", str(other), "--kind", "2d"], tmp_path)  # creates the model
    assert r.returncode == 0, r.stderr
    assert "1 views into model 'pipe'" in r.stdout

    r = _run(["remove", "gear"], tmp_path)
    assert r.returncode == 0 and "removed model 'gear'" in r.stdout
    r = _run(["list"], tmp_path)
    assert "gear" not in r.stdout.replace("pipe", "") and "1 models" in r.stdout


def test_bad_input_is_named(tmp_path):
    r = _run(["add", "x y"], tmp_path)
    assert r.returncode == 2 and "'x y'" in r.stderr
    r = _run(["add", "x", "--kind", "4d"], tmp_path)
    assert r.returncode == 2 and "'4d'" in r.stderr
    r = _run(["add", "x", "--threshold", "2"], tmp_path)
    assert r.returncode == 2 and "threshold" in r.stderr
    folder = tmp_path / "unnamed"
    folder.mkdir()
    (folder / "picture.png").write_bytes(png_bytes(textured_rgb(4)))
    r = _run(["import", "x", str(folder)], tmp_path)
    assert r.returncode == 2 and "'picture.png' names no viewpoint" in r.stderr
    r = _run(["import", "x", str(tmp_path / "missing")], tmp_path)
    assert r.returncode == 2 and "is not a folder" in r.stderr
    (folder / "manifest.json").write_text(json.dumps([{"file": "picture.png", "viewpoint": 5}]))
    r = _run(["import", "x", str(folder)], tmp_path)
    assert r.returncode == 2 and "viewpoint must be 1, 2 or 3" in r.stderr
    r = _run(["remove", "nobody"], tmp_path)
    assert r.returncode == 2 and "no object model named 'nobody'" in r.stderr


def test_teach_names_an_unreachable_cell_and_bad_options(tmp_path):
    from tests.utils.factories import free_port

    url = f"http://127.0.0.1:{free_port()}"
    r = _run(["teach", "gear", "--token", "t", "--url", url], tmp_path)
    assert r.returncode == 2 and f"cannot reach the cell at {url}" in r.stderr
    r = _run(["teach", "gear", "--token", "t", "--url", url, "--background", "later"], tmp_path)
    assert r.returncode == 2 and "'later'" in r.stderr
    r = _run(["teach", "gear", "--token", "t", "--url", url, "--viewpoints", "1,x"], tmp_path)
    assert r.returncode == 2 and "'1,x'" in r.stderr
    for bad in ("2", "5/4", "0/4", "1/13", "a/b"):
        r = _run(["teach", "gear", "--token", "t", "--url", url, "--round", bad], tmp_path)
        assert r.returncode == 2 and f"'{bad}'" in r.stderr, (bad, r.stderr)
    r = _run(["teach", "gear", "--token", "t", "--url", url, "--round", "2/4"], tmp_path)
    assert "round 2/4: the object turned by 90.0 deg" in r.stdout
    assert r.returncode == 2 and f"cannot reach the cell at {url}" in r.stderr
