"""Bug (fault campaign): the empty-belt backgrounds lived in memory only, so after a restart
every inspection failed ``no empty-belt background`` until a model was taught again.  They
are stored in ``station_backgrounds`` and loaded at start-up now."""

from __future__ import annotations

import numpy as np
import pytest

from backend.db.session import Database
from backend.inspection import recovery
from backend.runtime import ensure_cell_row
from tests.utils.factories import make_settings, migrate


@pytest.fixture
def url(tmp_path):
    settings = make_settings(tmp_path)
    migrate(settings)
    return settings.database_url


@pytest.fixture
async def db(url):
    d = Database(url)
    yield d
    await d.dispose()


async def test_bug_restart_forgets_backgrounds(db):
    cell = await ensure_cell_row(db, "cell-1")
    img = np.random.default_rng(0).integers(0, 255, (24, 32, 3), dtype=np.uint8)
    key = (0.1, -0.2, 0.3, 0.4, 0.0)
    await recovery.save_background(db, cell, key, img)
    await recovery.save_background(db, cell, key, img[::-1].copy())  # replaced, not added
    got = await recovery.load_backgrounds(db, cell)
    assert list(got) == [key] and np.array_equal(got[key], img[::-1])
    assert await recovery.load_backgrounds(db, await ensure_cell_row(db, "cell-2")) == {}
