"""The simulated suction cup and bins: sealing on contact, the payload carried, landing truth."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from robot.errors import DriverError
from robot.kinematics import T_base_ee, ik
from robot.pick import T_EE_SUCTION_CUP, tool_flange_pose
from robot.sim import SimEngine
from robot.sim.bins import BinSpec, default_bins
from robot.sim.catalogue import CATALOGUE
from robot.sim.gripper import payload_mass_kg, suction_point
from robot.sim.imaging import capture
from robot.sim.obstacles import collision_world
from robot.sim.poses import standard_configurations
from robot.sim.world import WorldLayout

NAME = "wheel-steel"


def _q_lip(engine: SimEngine, p_lip) -> np.ndarray:
    pose = tool_flange_pose(np.asarray(p_lip, float))
    return ik(pose, roll=0.0, seed=engine.arm_model.q_ready)


def _spawn_at_station(engine: SimEngine, name: str = NAME, yaw: float = 0.3):
    engine.clear_objects()
    engine.configure_conveyor(mode="index", running=False)
    spec = engine.config.layout.conveyor
    return engine.spawn(name, s_m=spec.station_s_m, yaw_rad=yaw)


def _grasp_point(truth, name: str = NAME) -> np.ndarray:
    g = suction_point(name)
    return truth.T_base_obj[:3, :3] @ g + truth.T_base_obj[:3, 3]


def _cup_geoms(engine: SimEngine) -> np.ndarray:
    m = engine.model
    mats = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_MATERIAL, n) for n in ("cup", "tube")]
    return np.flatnonzero(np.isin(m.geom_matid, mats))


def test_cup_and_payload_sit_where_the_planner_says(engine):
    m = engine.model
    pid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "payload")
    q = standard_configurations()["top"]
    engine.set_joints(q)
    np.testing.assert_allclose(
        engine.data.xpos[pid], (T_base_ee(q) @ T_EE_SUCTION_CUP)[:3, 3], atol=1e-9
    )
    # The camera's mounting is untouched (hand-eye ground truth).
    cid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_CAMERA, "eye")
    np.testing.assert_allclose(m.cam_pos[cid], engine.config.camera.T_ee_cam[:3, 3], atol=1e-12)
    assert len(_cup_geoms(engine)) == 4


def test_cup_is_outside_the_camera_view(engine):
    q = standard_configurations()["top"]
    engine.clear_objects()
    spec = engine.config.camera.with_(noise_std_dn=0.0, motion_blur=False)
    with_cup = capture(engine, q, spec=spec).rgb
    geoms = _cup_geoms(engine)
    saved = engine._alpha[geoms].copy()
    engine._alpha[geoms] = 0.0
    try:
        without = capture(engine, q, spec=spec).rgb
    finally:
        engine._alpha[geoms] = saved
    assert np.array_equal(with_cup, without)


def test_suction_seals_only_on_contact_then_carries_the_part(engine):
    truth = _spawn_at_station(engine)
    g = _grasp_point(truth)
    engine.set_joints(_q_lip(engine, g + np.array([0.0, 0.0, 0.05])))
    report = engine.grip(True)
    assert report.on and not report.holding and "no part" in report.detail
    assert engine.arm_state().gripper_on and not engine.arm_state().holding
    # Lower the cup onto the part: with the suction on it seals on contact.
    engine.set_joints(_q_lip(engine, g - [0.0, 0.0, 0.002]))
    engine.advance(0.02)
    held = engine.held_object()
    assert held is not None and held[0] == truth.id and held[1] == NAME
    assert engine.arm_state().holding
    assert truth.id not in [o.id for o in engine.objects()]  # off the belt's books
    pid = mujoco.mj_name2id(engine.model, mujoco.mjtObj.mjOBJ_BODY, "payload")
    assert engine.model.body_mass[pid] == pytest.approx(payload_mass_kg(NAME))
    np.testing.assert_allclose(held[2], truth.T_base_obj, atol=1e-3)
    # Hold still with the part: the controller carries the extra weight.
    q_hold = engine.arm_state().q
    tau0 = engine.controller.last_tau.copy()
    engine.advance(1.0)
    assert np.abs(engine.arm_state().q - q_hold).max() < 1e-4
    snap = engine.snapshot()
    name, slot = engine._item_slot[truth.id]
    mid = engine._slots[name][slot][0]
    np.testing.assert_allclose(snap.mocap_pos[mid], engine.held_object()[2][:3, 3], atol=1e-9)
    # The part's weight shows in the shoulder torque (q2 lifts it): m g r with r ~ 0.8 m.
    engine.grip(False)
    engine.advance(0.5)
    dtau = abs(tau0[1] - engine.controller.last_tau[1])
    assert dtau == pytest.approx(payload_mass_kg(NAME) * 9.81 * 0.8, rel=0.2)
    assert engine.model.body_mass[pid] < 1e-5


def test_release_over_the_belt_puts_the_part_back_and_elsewhere_on_the_floor(engine):
    truth = _spawn_at_station(engine)
    g = _grasp_point(truth)
    q_pick = _q_lip(engine, g - [0.0, 0.0, 0.002])
    engine.set_joints(q_pick)
    assert engine.grip(True).holding
    q_drop = _q_lip(engine, g + np.array([0.0, 0.1, 0.1]))
    engine.set_joints(q_drop)
    report = engine.grip(False)
    assert report.released_id == truth.id and "belt" in report.detail
    (back,) = engine.objects()
    assert back.id == truth.id and back.s_m == pytest.approx(truth.s_m + 0.1, abs=1e-3)
    # The part turned with the flange about the vertical (q1 changed).
    assert back.yaw_rad == pytest.approx(truth.yaw_rad + q_drop[0] - q_pick[0], abs=1e-6)
    # Picked again and dropped between the belt and the bins: it is on the floor.
    g = _grasp_point(back)
    engine.set_joints(_q_lip(engine, g - [0.0, 0.0, 0.002]))
    assert engine.grip(True).part_id == truth.id
    engine.set_joints(_q_lip(engine, (0.5, -0.5, 0.75)))
    assert "floor" in engine.grip(False).detail
    assert engine.objects() == []
    assert engine.landings()[-1].place == "floor"
    assert truth.id not in sum(engine.bins().values(), ())


def test_gripper_refuses_during_an_emergency_stop_and_keeps_the_part(engine):
    truth = _spawn_at_station(engine)
    engine.set_joints(_q_lip(engine, _grasp_point(truth) - [0.0, 0.0, 0.002]))
    assert engine.grip(True).holding
    engine.brake()
    try:
        with pytest.raises(DriverError, match="emergency stop"):
            engine.grip(False)
        assert engine.held_object() is not None
    finally:
        engine.clear_estop()
    engine.clear_objects()
    assert engine.held_object() is None
    with pytest.raises(ValueError, match="True or False"):
        engine.grip(1)  # type: ignore[arg-type]


def test_default_bins_are_apart_and_clear_of_the_cell():
    bins = default_bins()
    parts = {e.base_of for e in CATALOGUE.values() if e.trainable}
    assert {p for b in bins for p in b.parts} == parts
    assert sum(b.reject for b in bins) == 1
    world = collision_world()
    furniture = [b for b in world.boxes if not b.name.startswith("bin ")]
    for i, a in enumerate(bins):
        ca = a.corners_xy()
        for b in bins[i + 1 :]:
            cb = b.corners_xy()
            assert (
                ca[:, 0].max() <= cb[:, 0].min()
                or cb[:, 0].max() <= ca[:, 0].min()
                or ca[:, 1].max() <= cb[:, 1].min()
                or cb[:, 1].max() <= ca[:, 1].min()
            ), (a.name, b.name)
        for box in furniture:
            assert (
                ca[:, 0].max() <= box.lower[0]
                or ca[:, 0].min() >= box.upper[0]
                or ca[:, 1].max() <= box.lower[1]
                or ca[:, 1].min() >= box.upper[1]
            ), (a.name, box.name)
        assert a.contains(a.drop_point) and not a.contains(
            a.drop_point + np.array([a.size_m, 0, 0])
        )


def test_bin_specs_are_validated():
    with pytest.raises(ValueError, match="bin name"):
        BinSpec("a b", ("x",), (0.0, 0.8))
    with pytest.raises(ValueError, match="centre_xy"):
        BinSpec("a", ("x",), (math.nan, 0.8))
    with pytest.raises(ValueError, match="takes no part"):
        BinSpec("a", (), (0.0, 0.8))
    with pytest.raises(ValueError, match="two bins"):
        WorldLayout(bins=(BinSpec("a", ("x",), (0, 0.8)), BinSpec("b", ("x",), (0, -0.8))))
    with pytest.raises(KeyError, match="no bin 'nope'"):
        WorldLayout().bin("nope")


def test_every_default_bin_takes_its_parts_from_the_station():
    from robot.pick import plan_pick_place

    layout = WorldLayout()
    world = collision_world(layout)
    station = layout.conveyor.T_base_item(layout.conveyor.station_s_m, 0.0, 0.5)
    # The only patches of these the cup seals on are within 2 cm of the belt, where the
    # collision model's tool sphere refuses the descent: their drops are planned with a
    # grasp on the top.
    low = {"pipe-flange", "bracket-upright", "bracket-flat"}
    for b in layout.bins:
        names = [
            n
            for n, e in CATALOGUE.items()
            if (b.reject and not e.trainable) or (e.base_of in b.parts)
        ]
        assert names, b.name
        for name in names:
            bounds = CATALOGUE[name].geometry().bounds
            height = float(bounds[1, 2])
            plan = plan_pick_place(
                standard_configurations()["top"],
                station,
                height,
                b.drop_point,
                object_radius_m=float(np.abs(bounds[:, :2]).max()),
                grasp_obj=(0.0, 0.0, height) if name in low else suction_point(name),
                world=world,
            )
            assert not world.collides(plan.q_drop), (b.name, name)
