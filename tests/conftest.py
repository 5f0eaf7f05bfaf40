"""Fixtures shared by every test package."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

# MuJoCo picks its OpenGL back end when it is first imported: render headless (EGL), as
# `make test` and .ci/run do.
os.environ.setdefault("MUJOCO_GL", "egl")

from backend.settings import Settings

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")
def data_dir() -> Path:
    """The public data directory from the settings (``VISIONCELL_DATA_DIR``, default
    ``../shared/data`` beside the repository); tests that need it skip when it is absent."""
    path = Settings().data_dir
    if not path.is_absolute():
        path = (REPO / path).resolve()
    if not path.is_dir():
        pytest.skip(f"public data directory {path} is absent (set VISIONCELL_DATA_DIR)")
    return path
