"""A teach stores every view it shot; one with too few features (a roll of the top view
that sees a plain face, say) used to refuse the whole round, and the CLI's teach ended
with an error although the other views were good.  Now such a view is left out and said,
and the round is refused only when every top view is that weak -- nothing partial is
stored either way."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest
from sqlalchemy import func, select

from backend.db.models import TrainedView
from backend.db.session import Database
from backend.recognition import models as msvc
from backend.recognition.index import LiveIndex
from backend.recognition.views import TooFewFeatures, ViewInput, add_views
from tests.utils.models import textured_rgb


def _flat() -> np.ndarray:
    return np.full((120, 120, 3), 90, np.uint8)


def _run(settings, views, **kw):
    async def go():
        db = Database(settings.database_url)
        try:
            live = LiveIndex(method="orb", max_features=200)
            m = await msvc.create_model(db, msvc.ModelFields(name="box", kind="3d"))
            try:
                rows = await add_views(db, live, m.id, views, **kw)
                out = [(r.viewpoint, r.roll_rad) for r in rows]
            except TooFewFeatures as exc:
                out = exc
            async with db.session() as s:
                n = await s.scalar(select(func.count()).select_from(TrainedView))
            return out, n, len(live)
        finally:
            await db.dispose()

    return asyncio.run(go())


def _views():
    return [
        ViewInput(textured_rgb(1), 1, None, roll_rad=0.0, name="top roll 0"),
        ViewInput(_flat(), 1, None, roll_rad=-2.0, name="top roll -115"),
        ViewInput(textured_rgb(2), 2, None, roll_rad=0.0, name="side"),
    ]


def test_a_weak_view_is_left_out_and_said(settings):
    skipped: list[tuple[int, str]] = []
    rows, n, indexed = _run(settings, _views(), skipped=skipped, needs_viewpoint=1)
    assert rows == [(1, 0.0), (2, 0.0)] and n == 2 and indexed == 2
    assert [k for k, _ in skipped] == [1]
    assert "top roll -115" in skipped[0][1] and "features" in skipped[0][1]


def test_without_a_list_a_weak_view_refuses_them_all(settings):
    err, n, indexed = _run(settings, _views())
    assert isinstance(err, TooFewFeatures) and "top roll -115" in err.detail
    assert n == 0 and indexed == 0


@pytest.mark.parametrize("weak_side", [False, True])
def test_every_top_view_weak_refuses_the_round(settings, weak_side):
    views = [
        ViewInput(_flat(), 1, None, roll_rad=0.0, name="top roll 0"),
        ViewInput(_flat(), 1, None, roll_rad=2.0, name="top roll 115"),
        ViewInput(_flat() if weak_side else textured_rgb(3), 2, None, name="side"),
    ]
    err, n, indexed = _run(settings, views, skipped=[], needs_viewpoint=1)
    assert isinstance(err, TooFewFeatures) and "top roll 0" in err.detail
    assert n == 0 and indexed == 0
