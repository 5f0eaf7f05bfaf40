"""The wheel works without the repository: console and migrations ship as package data.

Builds the wheel (``pip wheel --no-deps``, with the build backend pip finds as for ``make
install``), checks what it carries, installs it non-editable into a fresh virtualenv whose
dependencies come from this one (a ``.pth`` line; the editable install of this checkout is
not visible there), then runs ``visioncell db upgrade`` against a temporary SQLite file and
serves ``/`` from the installed files, all from a directory outside the repository.
"""

from __future__ import annotations

import os
import signal
import socket
import sqlite3
import subprocess
import sys
import sysconfig
import time
import urllib.request
import zipfile
from pathlib import Path

import pytest

from backend.db.migrate import head_revision

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[1]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("dist")
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(out), str(ROOT)],
        check=True,
        capture_output=True,
        timeout=600,
    )
    (whl,) = out.glob("visioncell-*.whl")
    return whl


@pytest.fixture(scope="module")
def venv(wheel, tmp_path_factory) -> Path:
    """A virtualenv with the wheel installed (not editable); dependencies from ours."""
    env_dir = tmp_path_factory.mktemp("venv")
    subprocess.run(
        [sys.executable, "-m", "venv", "--without-pip", "--system-site-packages", str(env_dir)],
        check=True,
        timeout=120,
    )
    py = env_dir / "bin" / "python"
    site = subprocess.run(
        [str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout.strip()
    ours = {sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]}
    Path(site, "visioncell-test-deps.pth").write_text("\n".join(sorted(ours)) + "\n")
    subprocess.run(
        [sys.executable, "-m", "pip", "--python", str(py), "install", "--no-deps", "-q",
         str(wheel)],
        check=True,
        capture_output=True,
        timeout=300,
    )  # fmt: skip
    return env_dir


def _env(tmp: Path, **extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("VISIONCELL_", "PYTHON"))}
    return env | {"VISIONCELL_VAR_DIR": str(tmp / "var")} | extra


def test_wheel_carries_the_console_and_the_migrations(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    assert "backend/web/index.html" in names
    web_js = {n for n in names if n.startswith("backend/web/") and n.endswith(".js")}
    repo_js = {f"backend/{p.relative_to(ROOT)}" for p in (ROOT / "web").rglob("*.js")}
    assert repo_js and web_js == repo_js
    assert {"backend/migrations/env.py", "backend/migrations/script.py.mako"} <= names
    versions = {
        f"backend/migrations/versions/{p.name}" for p in ROOT.glob("migrations/versions/*.py")
    }
    assert versions and versions <= names
    assert not any("__pycache__" in n or n.endswith(".pyc") for n in names)
    assert not any(n.startswith(("web/", "migrations/")) for n in names)  # no top-level names


def test_installed_package_migrates_and_serves_from_its_own_files(venv, tmp_path):
    py, cli = venv / "bin" / "python", venv / "bin" / "visioncell"
    where = subprocess.run(
        [str(py), "-c", "import backend.app as a, backend.db.migrate as m; "
         "print(a.__file__); print(a.WEB_DIR); print(m.MIGRATIONS_DIR)"],
        cwd=tmp_path, env=_env(tmp_path), check=True, capture_output=True, text=True,
    ).stdout.split()  # fmt: skip
    assert all(Path(p).is_relative_to(venv) for p in where), where

    db = tmp_path / "cell.db"
    url = f"sqlite+aiosqlite:///{db}"
    done = subprocess.run(
        [str(cli), "db", "upgrade"], cwd=tmp_path, env=_env(tmp_path, VISIONCELL_DATABASE_URL=url),
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    with sqlite3.connect(db) as conn:
        (rev,) = conn.execute("SELECT version_num FROM alembic_version").fetchone()
    assert rev == head_revision()

    port = _free_port()
    env = _env(
        tmp_path,
        VISIONCELL_DATABASE_URL=url,
        VISIONCELL_HTTP_PORT=str(port),
        VISIONCELL_VISER_PORT=str(_free_port()),
        VISIONCELL_DRIVER="ideal",
        VISIONCELL_VIEW3D_ENABLED="false",
        MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"),
    )
    log = tmp_path / "serve.log"
    with log.open("wb") as out:
        proc = subprocess.Popen(
            [str(cli), "serve"], cwd=tmp_path, env=env, stdout=out, stderr=subprocess.STDOUT
        )
    try:
        page = None
        deadline = time.monotonic() + 120.0
        while time.monotonic() < deadline and proc.poll() is None:
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=5) as r:
                    page = r.read()
                break
            except OSError:
                time.sleep(0.5)
        assert page is not None, log.read_text(errors="replace")[-3000:]
        assert page == (ROOT / "web" / "index.html").read_bytes()
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=10)
