"""``visioncell recipes list | show | create | activate`` as a user runs them: real
processes against a running cell, with tokens printed by ``visioncell user add``; the
API's role rules hold (a viewer cannot create, an operator selects, only an engineer
creates) and refusals exit 2 naming why."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import httpx
import pytest

from backend.app import create_app
from tests.utils.cli import cli_token
from tests.utils.factories import make_settings, migrate
from tests.utils.servers import run_uvicorn


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("cli-recipes")
    layout = tmp / "cell.toml"  # a real cell whose layout has the bin the recipe names
    layout.write_text(
        "[station]\nx_m = 0.8\ny_m = 0.0\nsurface_z_m = 0.45\n\n"
        '[[bins]]\nname = "bin-a"\nparts = ["wheel-a"]\ndrop_m = [0.31, 0.61, 0.30]\n'
    )
    settings = make_settings(tmp).model_copy(update={"cell_layout": layout})
    migrate(settings)
    tokens = {role: cli_token(settings, f"cli-{role}", role)
              for role in ("viewer", "operator", "engineer")}  # fmt: skip
    with run_uvicorn(create_app(settings)) as srv:
        yield srv, tokens


def _cli(srv, token, *args):
    env = {**os.environ, "VISIONCELL_TOKEN": token, "COLUMNS": "200"}
    return subprocess.run(
        [sys.executable, "-m", "backend.cli", "recipes", *args, "--url", srv.base],
        capture_output=True, text=True, env=env, timeout=120,
    )  # fmt: skip


def test_create_list_show_and_activate(served):
    srv, tok = served
    eng = {"Authorization": f"Bearer {tok['engineer']}"}
    r = httpx.post(f"{srv.base}/api/models", json={"name": "wheel-a", "kind": "2d"}, headers=eng)
    assert r.status_code == 201, r.text

    r = _cli(srv, tok["engineer"], "create", "wheels", "--number", "12", "--policy", "top-only",
             "--max-views", "1", "--sort", "--threshold", "0.35", "--model", "wheel-a",
             "--bin", "wheel-a=bin-a", "--reason", "new line")  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "no. 12 wheels: top-only, 1 view(s), sort on, threshold 0.35" in r.stdout, r.stdout
    r = _cli(srv, tok["engineer"], "create", "steel", "--number", "13", "--belt-mode", "index")
    assert r.returncode == 0, r.stderr

    r = _cli(srv, tok["viewer"], "list")
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    assert lines[-1] == "2 recipe(s); active: none", r.stdout
    assert "no. 12 wheels" in lines[0] and "no. 13 steel" in lines[1] and "index" in lines[1]

    # An operator selects by the number a PLC would send; the list marks it.
    r = _cli(srv, tok["operator"], "activate", "--number", "13", "--reason", "changeover")
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("active: #") and "steel" in r.stdout, r.stdout
    r = _cli(srv, tok["viewer"], "list")
    assert r.stdout.splitlines()[-1] == "2 recipe(s); active: steel", r.stdout
    assert [ln[0] for ln in r.stdout.splitlines()[:2]] == [" ", "*"]

    listed = httpx.get(f"{srv.base}/api/recipes", headers=eng).json()
    wheels = next(x for x in listed["data"] if x["name"] == "wheels")
    r = _cli(srv, tok["viewer"], "show", str(wheels["id"]))
    assert r.returncode == 0, r.stderr
    shown = json.loads(r.stdout)
    assert (shown["models"], shown["bins"], shown["sort"], shown["threshold"]) == (
        ["wheel-a"], {"wheel-a": "bin-a"}, True, 0.35)  # fmt: skip
    r = _cli(srv, tok["operator"], "activate", str(wheels["id"]))
    assert r.returncode == 0 and "wheels" in r.stdout, r.stderr

    audit = httpx.get(f"{srv.base}/api/audit?kind=recipe", headers=eng).json()["data"]
    acts = [(e["actor"], e["action"], e["reason"]) for e in reversed(audit)]
    assert acts == [("cli-engineer", "create", "new line"), ("cli-engineer", "create", ""),
                    ("cli-operator", "activate", "changeover"), ("cli-operator", "activate", "")]  # fmt: skip


def test_refusals_exit_2_and_name_why(served):
    srv, tok = served
    r = _cli(srv, tok["operator"], "create", "nope", "--number", "50")
    assert r.returncode == 2 and "HTTP 403" in r.stderr, (r.stdout, r.stderr)
    r = _cli(srv, tok["viewer"], "activate", "1")
    assert r.returncode == 2 and "HTTP 403" in r.stderr, r.stderr
    r = _cli(srv, tok["operator"], "activate", "--number", "99")
    assert r.returncode == 2 and "no recipe numbered 99" in r.stderr, r.stderr
    r = _cli(srv, tok["operator"], "activate", "9999")
    assert r.returncode == 2 and "HTTP 404" in r.stderr, r.stderr
    r = _cli(srv, tok["engineer"], "create", "bad", "--number", "0")
    assert r.returncode == 2 and "--number must be in 1..9999" in r.stderr, r.stderr
    r = _cli(srv, tok["engineer"], "create", "bad", "--number", "51", "--bin", "nobin")
    assert r.returncode == 2 and "MODEL=BIN" in r.stderr, r.stderr
    r = _cli(srv, tok["engineer"], "create", "bad", "--number", "52", "--model", "ghost")
    assert r.returncode == 2 and "HTTP 422" in r.stderr and "ghost" in r.stderr, r.stderr
    r = _cli(srv, tok["operator"], "activate")
    assert r.returncode == 2 and "one of the two" in r.stderr, r.stderr
    r = _cli(srv, "not-a-token", "list")
    assert r.returncode == 2 and "HTTP 401" in r.stderr, r.stderr
