"""The simulated cell behind the cell-world protocols: its conveyor, layout and truth."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest

from robot.cellworld import CellLayout, TruthSource
from robot.drivers.conveyor import Conveyor
from robot.sim import SimConveyor, SimEngine
from robot.sim.layout import SimObjectTruth, cell_layout


def test_the_simulators_layout_is_its_world(engine: SimEngine):
    world = engine.config.layout
    layout = cell_layout(world)
    assert isinstance(layout, CellLayout) and layout.source == "simulator"
    np.testing.assert_allclose(layout.station_point, world.conveyor.station_point)
    assert layout.belt is not None and layout.belt_end_y_m == world.conveyor.end_y_m
    assert [b.name for b in layout.bins] == [b.name for b in world.bins]
    for mine, theirs in zip(layout.bins, world.bins, strict=True):
        np.testing.assert_allclose(mine.drop_point, theirs.drop_point)
        np.testing.assert_allclose(mine.corners_xy(), theirs.corners_xy())
        assert (mine.parts, mine.reject) == (tuple(theirs.parts), theirs.reject)
    assert layout.bin_for("wheel-steel").name == "bin-wheel-steel"
    assert layout.bin_for("no-such-part").reject


def test_the_simulated_belt_is_a_conveyor_the_cell_drives(engine: SimEngine):
    belt = SimConveyor(engine)
    assert isinstance(belt, Conveyor) and belt.controllable

    async def go() -> None:
        await belt.set_mode("index", speed_m_s=0.2)
        st = await belt.start(mode="continuous", speed_m_s=0.1)
        assert (st.running, st.mode, st.speed_m_s) == (True, "continuous", 0.1)
        t0 = belt.travel_at()
        engine.advance(1.0)
        assert belt.travel_at() - t0 == pytest.approx(0.1, abs=1e-9)
        st = await belt.stop()
        assert not st.running and st.mode == "continuous"
        st = await belt.set_mode("index", speed_m_s=0.2)
        assert (st.running, st.mode, st.speed_m_s) == (False, "index", 0.2)

    asyncio.run(go())


def test_the_truth_names_the_nearest_object_moved_back_along_the_belt(engine: SimEngine):
    engine.clear_objects()
    truth = SimObjectTruth(engine)
    assert isinstance(truth, TruthSource)
    assert truth.object_near(np.zeros(3)) is None
    o = engine.spawn("wheel-steel", s_m=1.3, lateral_m=0.0, yaw_rad=0.2)
    try:
        p = o.T_base_obj[:3, 3]
        got = truth.object_near(p + np.array([0.0, -0.25, 0.0]), back_m=0.25)
        assert got is not None and got["id"] == o.id and got["name"] == "wheel-steel"
        np.testing.assert_allclose(np.asarray(got["T_base_obj"])[:3, 3], p - [0.0, 0.25, 0.0])
        assert got["yaw_rad"] == pytest.approx(0.2)
    finally:
        engine.remove(o.id)
