"""A part lying at the station when an indexing belt starts is held there, not carried past.

The symptom (the operator's path): six objects laid out as on the demo belt, the first at the
station, the belt stopped; *Start* of a sorted run and *Start belt*: the first object rode
away before the arm looked at it, went round the belt and was inspected last, so the rows no
longer came in belt order.  Indexing held only parts arriving from upstream; one already at
the station (placed there, e.g. *Place at the station*) was never held.  Now a part at the
station that was never held is held first, and one released goes on as before.
"""

from __future__ import annotations

import pytest

from robot.sim import ConveyorSpec
from robot.sim.world import BeltItem, Conveyor

SPEC = ConveyorSpec()


def test_a_part_placed_at_the_station_is_held_until_released():
    st = SPEC.station_s_m
    c = Conveyor(SPEC, speed_m_s=0.2, mode="index", dwell_s=None, running=False)
    c.items[1] = BeltItem(1, "first", st, 0.0, 0.0)  # placed at the station, belt stopped
    c.items[2] = BeltItem(2, "second", st - 0.42, 0.0, 0.0)
    c.configure(running=True)
    c.advance(5.0)
    assert c.state.at_station
    assert c.items[1].s_m == pytest.approx(st) and c.items[2].s_m == pytest.approx(st - 0.42)
    c.release()  # inspected: the belt brings the next one
    c.advance(5.0)
    assert c.state.at_station
    assert c.items[2].s_m == pytest.approx(st, abs=1e-9)
    assert c.items[1].s_m == pytest.approx(st + 0.42, abs=1e-9)
    c.release()
    c.advance(1.0)  # nothing upstream: both ride on
    assert c.items[2].s_m == pytest.approx(st + 0.2, abs=1e-9)


def test_with_a_dwell_the_placed_part_waits_its_dwell_then_goes_on():
    st = SPEC.station_s_m
    c = Conveyor(SPEC, speed_m_s=0.2, mode="index", dwell_s=1.0, running=True)
    c.items[1] = BeltItem(1, "first", st, 0.0, 0.0)
    c.advance(0.5)
    assert c.items[1].s_m == pytest.approx(st)
    c.advance(1.0)  # 0.5 s more of dwell, then 0.5 s of travel
    assert c.items[1].s_m == pytest.approx(st + 0.1, abs=1e-9)
