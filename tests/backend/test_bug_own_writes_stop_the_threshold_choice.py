"""The cell's own writes no longer stop its threshold choice.

The symptom: the last round of a teach chose the automatic threshold and reported "not
chosen" (the threshold in force stayed at its start value), and the threshold keeper's
recomputations were stopped ("superseded") one after another while nothing but the cell
itself had written.  The index sync polls the database's change counter, which the cell's
own writes move too (its views, its model's measured height); each poll then applied an
empty diff and told the listeners of a change, which the keeper takes as "the views changed
meanwhile".  Now an empty diff is no change: the listeners hear only of real ones.
"""

from __future__ import annotations

import asyncio

import numpy as np

from backend.db.session import Database
from backend.jobs import JobManager
from backend.recognition.autothreshold import ThresholdKeeper
from backend.recognition.index import IndexedModel, LiveIndex
from tests.utils.factories import make_settings, migrate
from tests.utils.models import textured_rgb

#: Bounds a hang only.
TIMEOUT_S = 300.0


def _indexed(live: LiveIndex, n_models: int = 1) -> list[IndexedModel]:
    models = [IndexedModel(k + 1, f"m{k}", f"m{k}", "default", "2d", None) for k in range(n_models)]
    vid = 0
    for m in models:
        live.put_model(m)
        for seed in (3, 4, 5):
            vid += 1
            live.add_view(m, vid, 1, live.extract(textured_rgb(10 * m.id + seed), None))
    return models


def _as_stored(live: LiveIndex, models: list[IndexedModel]):
    """The database as this process wrote it: its models and views."""
    views = {vid: (mid, live.method, live.version) for mid in (m.id for m in models)
             for vid in live.views_of(mid)}  # fmt: skip
    return {m.id: m for m in models}, views


def test_a_sync_that_finds_nothing_new_tells_no_listener():
    live = LiveIndex()
    models = _indexed(live)
    heard: list[int] = []
    live.add_listener(lambda: heard.append(1))
    diff = live.diff(*_as_stored(live, models))
    assert diff.empty
    assert live.apply(diff, [])
    assert heard == []
    # A real change made by another process (a rename) is still told.
    renamed = [IndexedModel(1, "renamed", "m0", "default", "2d", None)]
    diff = live.diff(*_as_stored(live, renamed))
    assert not diff.empty and live.apply(diff, [])
    assert heard


def test_the_teach_choice_survives_the_syncs_of_its_own_writes(tmp_path):
    """A choice running while the sync applies the cell's own writes again is stored."""
    settings = make_settings(tmp_path)
    migrate(settings)

    async def run() -> None:
        db = Database(settings.database_url)
        live = LiveIndex()
        keeper = ThresholdKeeper(db, live, JobManager(), quiet_s=0.0,
                                 backgrounds=lambda: [np.full((240, 320, 3), 90, np.uint8)])  # fmt: skip
        keeper.start()
        try:
            async with keeper.holding():
                models = _indexed(live, 2)
                stored = _as_stored(live, models)

                def report(_f: float, msg: str) -> None:
                    if msg.startswith("held-out query"):  # the sync polls meanwhile
                        live.apply(live.diff(*stored), [])

                outcome = await keeper.choose(report)
            assert outcome.stored, outcome.reason
            assert keeper.superseded == 0
        finally:
            await keeper.stop()
            await db.dispose()

    asyncio.run(asyncio.wait_for(run(), TIMEOUT_S))
