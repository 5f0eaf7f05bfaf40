"""The light balance in the simulated cell: models taught under the normal light, the lamps
given a warm cast, the empty-belt background grabbed again; the inspection measures the
cast on the belt round the object, scales the views back and stores the gain with each
view; with the balance off nothing is applied (issue 14, the colour-cast target).  The
simulator's cast is not a pure per-channel change (its ambient light stays white), and the
balance does not raise the scores there (README, "Teach and inspect")."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest
from sqlalchemy import select

from backend.db.migrate import upgrade
from backend.db.models import InspectionImage
from backend.inspection import service
from backend.runtime import CellRuntime
from benchmarks.inspection import _settings, _teach_all

pytestmark = pytest.mark.slow

CAST = np.array([1.0, 0.85, 0.6], dtype=np.float32)  # the benchmark's warm cast


async def _run(tmp) -> dict:
    settings = _settings(tmp, 20.0)
    await asyncio.to_thread(upgrade, settings.database_url)
    out: dict = {}
    async with CellRuntime(settings, view3d=False) as rt:
        engine = rt.sim
        station = engine.config.layout.conveyor.station_s_m
        await _teach_all(rt, ["gear-housing", "junction-box"])
        ctx = await service.context(rt)
        base = engine._light_base.copy()
        engine._light_base[:] = base * CAST
        try:
            engine.clear_objects()
            await service.grab_background(rt)
            engine.spawn("gear-housing", s_m=station, yaw_rad=0.6)
            for balance in (False, True):
                opts = service.InspectOptions(wait_s=20.0, max_views=1, policy="top-only",
                                              balance_light=balance)  # fmt: skip
                row = await service.inspect_object(ctx, opts)
                async with rt.database.session() as session:
                    metas = list(await session.scalars(
                        select(InspectionImage.scores)
                        .where(InspectionImage.inspection_id == row["id"])
                    ))  # fmt: skip
                out[balance] = (row, metas)
        finally:
            engine._light_base[:] = base
    return out


def test_cast_is_measured_on_the_belt_and_undone(tmp_path):
    out = asyncio.run(_run(tmp_path))
    (plain, plain_meta), (bal, bal_meta) = out[False], out[True]
    assert plain_meta[0]["light_gain"] is None  # off: nothing applied, nothing claimed
    gain = np.array(bal_meta[0]["light_gain"])
    # The belt's colour changed by the cast (the ambient light stays white, so a little
    # less than the lamps' own factor in green and blue).
    assert gain[0] == pytest.approx(1.0, abs=0.05), gain
    assert 1.05 < gain[1] <= 1 / 0.85 + 0.02 and 1.3 < gain[2] <= 1 / 0.6 + 0.02, gain
    assert bal["decision"] == "recognized" and bal["model"] == "gear-housing", bal["reason"]
    assert plain["decision"] == "recognized" and plain["model"] == "gear-housing", plain["reason"]
