"""The ``visioncell`` command line, run as a real process."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from tests.utils.factories import TEST_SECRET


def _run(args, tmp_path, **env):
    full = {
        **os.environ,
        "VISIONCELL_DATABASE_URL": f"sqlite+aiosqlite:///{tmp_path / 'cli.db'}",
        "VISIONCELL_SECRET_KEY": TEST_SECRET,
        **env,
    }
    return subprocess.run(
        [sys.executable, "-m", "backend.cli", *args],
        capture_output=True,
        text=True,
        env=full,
        timeout=60,
    )


def test_user_add_prints_the_token_alone_on_the_last_line(tmp_path):
    r = _run(["user", "add", "carla", "--role", "engineer"], tmp_path)
    assert r.returncode == 0, r.stderr
    token = r.stdout.strip().splitlines()[-1]
    assert token.startswith("vc_") and " " not in token and len(token) > 40
    again = _run(["user", "add", "carla"], tmp_path)
    assert again.returncode == 2 and "user 'carla' already exists" in again.stderr


def test_user_add_names_a_bad_role(tmp_path):
    r = _run(["user", "add", "dan", "--role", "admin"], tmp_path)
    assert r.returncode == 2
    assert "role must be one of viewer, operator, engineer, got 'admin'" in r.stderr


def test_bad_setting_is_reported_with_its_value(tmp_path):
    r = _run(["user", "add", "eve"], tmp_path, VISIONCELL_DRIVER="robotic")
    assert r.returncode == 2
    assert "driver" in r.stderr and "'robotic'" in r.stderr


def test_db_downgrade_and_upgrade(tmp_path):
    assert _run(["db", "upgrade"], tmp_path).returncode == 0
    r = _run(["db", "downgrade", "base"], tmp_path)
    assert r.returncode == 0 and "downgraded to base" in r.stdout
    r = _run(["db", "upgrade"], tmp_path)
    assert r.returncode == 0 and "upgraded to head" in r.stdout


@pytest.mark.parametrize(
    "args", [["--help"], ["serve", "--help"], ["db", "--help"], ["user", "add", "--help"]]
)
def test_help_is_useful(tmp_path, args):
    r = _run(args, tmp_path)
    assert r.returncode == 0
    assert "Usage" in r.stdout and len(r.stdout) > 200


def test_version(tmp_path):
    r = _run(["version"], tmp_path)
    assert r.returncode == 0 and r.stdout.strip()[0].isdigit()
