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


#: Where the last runs left each test file's time (seconds, setup to teardown of its tests),
#: in pytest's cache (``.pytest_cache``): the order of the next run.
FILE_SECONDS = "visioncell/file-seconds"


def _rank(item: pytest.Item) -> int:
    """0: the module is marked slow; 1: it drives a server or a browser (e2e); 2: the rest."""
    if item.get_closest_marker("slow") is not None:
        return 0
    if item.get_closest_marker("e2e") is not None or "e2e" in item.path.parts:
        return 1
    return 2


def _file_of(nodeid: str) -> str:
    return nodeid.split("::", 1)[0]


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Run the long modules first.

    ``make test`` hands whole files to two xdist workers in the order they were collected
    (``--dist loadfile --no-loadscope-reorder``).  A long file handed out last keeps one
    worker busy alone at the end, so the files go longest first (the classic greedy
    schedule), by their time in the last run that ran them (:data:`FILE_SECONDS`).  Files
    without one (new files; every file when there is no cache, as on CI) go before them, by
    their marks: modules with a slow test first, then e2e modules, then the rest.  Each
    module's tests keep their order and stay together, so module-scoped fixtures are still
    built once.  Both workers read the same cache, so they collect the same order.
    """
    cache = getattr(config, "cache", None)
    known: dict[str, float] = (cache.get(FILE_SECONDS, {}) if cache is not None else {}) or {}
    rank: dict[Path, int] = {}
    for item in items:
        rank[item.path] = min(rank.get(item.path, 2), _rank(item))

    def key(item: pytest.Item) -> tuple[int, int, float]:
        seconds = known.get(_file_of(item.nodeid))
        if seconds is None:
            return (0, rank[item.path], 0.0)
        return (1, 0, -float(seconds))

    items.sort(key=key)  # stable: collection order among equals


_SECONDS: dict[str, float] = {}


def pytest_runtest_logreport(report: pytest.TestReport) -> None:
    """Add up each file's time (on the xdist controller, from the workers' reports)."""
    _SECONDS[_file_of(report.nodeid)] = _SECONDS.get(_file_of(report.nodeid), 0.0) + float(
        report.duration
    )


def pytest_sessionfinish(session: pytest.Session) -> None:
    """Keep this run's file times for the next run's order (not from an xdist worker: its
    controller sees every file's reports)."""
    cache = getattr(session.config, "cache", None)
    if cache is None or hasattr(session.config, "workerinput") or not _SECONDS:
        return
    known = cache.get(FILE_SECONDS, {}) or {}
    known.update({f: round(t, 2) for f, t in _SECONDS.items()})
    cache.set(FILE_SECONDS, known)
