"""Fixtures of the simulated cell's tests: one engine per module (building one takes ~1 s)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from robot.sim import SimEngine


@pytest.fixture(scope="module")
def engine() -> Iterator[SimEngine]:
    """A fresh engine without its physics thread (tests step it with ``advance``)."""
    e = SimEngine()
    yield e
    e.stop()
