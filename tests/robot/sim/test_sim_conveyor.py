"""The belt: objects ride at the set speed, indexing stops them at the station."""

from __future__ import annotations

import numpy as np
import pytest

from robot.errors import SimError
from robot.sim import ConveyorSpec, SimConfig, SimEngine
from robot.sim.world import BeltItem, Conveyor, cleat_positions

SPEC = ConveyorSpec()


def test_items_move_at_the_set_speed():
    c = Conveyor(SPEC, speed_m_s=0.12, running=True)
    c.items[1] = _item(1, 0.1)
    for _ in range(100):
        c.advance(0.01)
    assert c.items[1].s_m == pytest.approx(0.1 + 0.12 * 1.0, abs=1e-12)
    c.configure(running=False)
    c.advance(5.0)
    assert c.items[1].s_m == pytest.approx(0.22, abs=1e-12)


def test_index_mode_stops_each_item_at_the_station_then_goes_on():
    st = SPEC.station_s_m
    c = Conveyor(SPEC, speed_m_s=0.2, mode="index", dwell_s=1.0, running=True)
    c.items[1] = _item(1, st - 0.3)
    c.items[2] = _item(2, st - 0.7)
    c.advance(1.5 + 0.5)  # 1.5 s to arrive, then 0.5 s of dwell
    assert c.items[1].s_m == pytest.approx(st, abs=1e-12)
    assert c.state.at_station
    c.advance(0.5)  # dwell over exactly now
    assert c.items[1].s_m == pytest.approx(st, abs=1e-12)
    c.advance(2.0)  # item 2 is 0.4 m upstream: 2 s
    assert c.items[2].s_m == pytest.approx(st, abs=1e-12)
    assert c.items[1].s_m == pytest.approx(st + 0.4, abs=1e-12)


def test_index_without_dwell_waits_for_release():
    st = SPEC.station_s_m
    c = Conveyor(SPEC, speed_m_s=0.5, mode="index", dwell_s=None, running=True)
    c.items[1] = _item(1, st - 0.5)
    c.advance(10.0)
    assert c.items[1].s_m == pytest.approx(st) and c.state.at_station
    c.release()
    c.advance(0.2)
    assert c.items[1].s_m == pytest.approx(st + 0.1)


def test_items_leaving_the_end_are_recycled_or_removed():
    c = Conveyor(SPEC, speed_m_s=1.0, running=True, at_end="recycle")
    c.items[1] = _item(1, SPEC.length_m - 0.05)
    assert c.advance(0.1) == []
    assert c.items[1].s_m == pytest.approx(0.05)
    c = Conveyor(SPEC, speed_m_s=1.0, running=True, at_end="remove")
    c.items[1] = _item(1, SPEC.length_m - 0.05)
    assert c.advance(0.1) == [1] and not c.items


def test_conveyor_rejects_bad_settings():
    c = Conveyor(SPEC)
    with pytest.raises(ValueError, match="speed_m_s"):
        c.configure(speed_m_s=-0.1)
    with pytest.raises(ValueError, match="mode"):
        c.configure(mode="sideways")
    with pytest.raises(ValueError, match="dwell_s"):
        c.configure(dwell_s=-1.0)


def test_stripes_show_the_belt_moving():
    a = cleat_positions(SPEC, 0.0, 9)
    b = cleat_positions(SPEC, 0.1, 9)
    np.testing.assert_allclose((b[:, 1] - a[:, 1]) % SPEC.length_m, 0.1, atol=1e-9)
    np.testing.assert_allclose(np.diff(a[:, 1]), SPEC.length_m / 9, atol=1e-9)
    assert np.all((b[:, 1] >= SPEC.start_y_m) & (b[:, 1] <= SPEC.end_y_m))


def test_objects_on_the_engine_belt_ride_at_the_set_speed(engine: SimEngine):
    engine.clear_objects()
    o = engine.spawn("wheel-steel", s_m=0.2, lateral_m=0.03, yaw_rad=0.4)
    engine.configure_conveyor(running=True, speed_m_s=0.15, mode="continuous")
    try:
        engine.advance(2.0)
    finally:
        engine.configure_conveyor(running=False)
    now = engine.truth.object(o.id)
    np.testing.assert_allclose(
        now.T_base_obj[:3, 3] - o.T_base_obj[:3, 3], [0.0, 0.3, 0.0], atol=1e-9
    )
    np.testing.assert_allclose(now.T_base_obj[:3, :3], o.T_base_obj[:3, :3], atol=1e-12)
    assert now.T_base_obj[2, 3] == SPEC.surface_z_m
    # The snapshot (what the camera draws) puts the object's body at its true pose.
    snap = engine.snapshot()
    name, slot = engine._item_slot[o.id]
    mocap = engine._slots[name][slot][0]
    np.testing.assert_allclose(snap.mocap_pos[mocap], now.T_base_obj[:3, 3])
    engine.remove(o.id)


def test_spawning_is_validated_and_slots_are_reused(engine: SimEngine):
    engine.clear_objects()
    with pytest.raises(
        ValueError, match="unknown catalogue name 'wheel-nope'; valid names: wheel-5spoke"
    ):
        engine.spawn("wheel-nope")
    with pytest.raises(ValueError, match="position along the belt"):
        engine.spawn("wheel-steel", s_m=-1.0)
    ids = [
        engine.spawn("oil-filter", s_m=0.3 * i).id for i in range(engine.config.slots_per_object)
    ]
    with pytest.raises(SimError, match="slots for 'oil-filter' are in use"):
        engine.spawn("oil-filter")
    engine.remove(ids[0])
    again = engine.spawn("oil-filter")
    assert again.id not in ids
    with pytest.raises(SimError, match="no object with id 12345"):
        engine.remove(12345)
    engine.clear_objects()
    assert engine.objects() == []


def test_engine_removes_objects_at_the_end_when_configured():
    e = SimEngine(SimConfig(belt_end="remove"))
    try:
        o = e.spawn("wheel-steel", s_m=SPEC.length_m - 0.01)
        e.configure_conveyor(running=True, speed_m_s=0.5)
        e.advance(0.1)
        assert e.objects() == []
        again = e.spawn("wheel-steel")  # its slot is free again
        assert again.id != o.id
    finally:
        e.stop()
    with pytest.raises(ValueError, match="belt_end"):
        SimConfig(belt_end="drop")


def test_yaw_of_spawned_objects_is_seeded():
    a, b = SimEngine(), SimEngine()
    try:
        ya = [a.spawn("wheel-steel").yaw_rad for _ in range(2)]
        yb = [b.spawn("wheel-steel").yaw_rad for _ in range(2)]
    finally:
        a.stop()
        b.stop()
    assert ya == yb and ya[0] != ya[1]


def _item(i: int, s: float) -> BeltItem:
    return BeltItem(i, "wheel-steel", s, 0.0, 0.0)
