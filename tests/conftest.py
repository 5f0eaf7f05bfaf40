"""Fixtures shared by every test package."""

from __future__ import annotations

import gc
import os
from pathlib import Path

import pytest

# MuJoCo picks its OpenGL back end when it is first imported: render headless (EGL), as
# `make test` and .ci/run do.
os.environ.setdefault("MUJOCO_GL", "egl")

from backend.settings import Settings

REPO = Path(__file__).resolve().parents[1]

# The test processes allocate in bursts (an app, its database sessions and frames per test,
# on a heap of a few hundred thousand objects from the imports): with CPython's default
# thresholds (700, 10, 10) the cyclic collector runs thousands of times per module and takes
# a large share of the suite's CPU.  Ten times fewer collections of each generation; garbage
# in cycles still goes, a little later.  (The servers the tests start keep the defaults.)
gc.set_threshold(10_000, 10, 10)


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


def _rank(item: pytest.Item) -> int:
    """0: the module is marked slow; 1: it drives a server or a browser (e2e); 2: the rest."""
    if item.get_closest_marker("slow") is not None:
        return 0
    if item.get_closest_marker("e2e") is not None or "e2e" in item.path.parts:
        return 1
    return 2


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Run the long modules first.

    ``make test`` hands whole files to two xdist workers in the order they were collected
    (``--dist loadfile --no-loadscope-reorder``).  A long file handed out last keeps one
    worker busy alone at the end, so modules with a slow or e2e test go first (the longest
    first is the classic greedy schedule); each module's tests keep their order and stay
    together, so module-scoped fixtures are still built once.
    """
    rank: dict[Path, int] = {}
    for item in items:
        rank[item.path] = min(rank.get(item.path, 2), _rank(item))
    items.sort(key=lambda item: rank[item.path])  # stable: collection order within a rank
