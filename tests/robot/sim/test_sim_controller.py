"""Joint control: the arm reaches commanded configurations within the tracking targets."""

from __future__ import annotations

import numpy as np
import pytest

from robot.model import ASEA
from robot.sim import ControllerGains, SimConfig, SimEngine
from robot.sim.controller import stop_trajectory
from robot.sim.poses import standard_configurations, standard_moves
from robot.trajectory import plan_joint_move

FINAL_MAX_RAD = 0.5e-3
RMS_MAX_RAD = 5e-3


def _run(engine: SimEngine, traj, extra_s: float = 1.5):
    reports = []
    engine.start_move(traj, reports.append)
    engine.advance(traj.duration_s + extra_s)
    assert len(reports) == 1
    return reports[0]


def test_standard_moves_meet_the_tracking_targets():
    engine = SimEngine()
    try:
        for name, traj in standard_moves(speed=1.0):
            r = _run(engine, traj)
            assert r.completed and r.reason == "done", name
            assert r.final_error_rad <= FINAL_MAX_RAD, name
            assert r.rms_tracking_error_rad <= RMS_MAX_RAD, name
            assert r.max_tracking_error_rad >= r.rms_tracking_error_rad > 0.0, name
            np.testing.assert_allclose(engine.arm_state().q, traj.goal, atol=FINAL_MAX_RAD)
            # The report's duration is the trajectory plus a short settling time.
            assert traj.duration_s <= r.duration_s <= traj.duration_s + 1.0, name
    finally:
        engine.stop()


def test_random_reachable_moves_meet_the_targets(engine: SimEngine):
    rng = np.random.default_rng(7)
    engine.set_joints(ASEA.q_home)
    q = np.array(ASEA.q_home)
    for _ in range(3):
        goal = rng.uniform(ASEA.lower + 0.05, ASEA.upper - 0.05)
        r = _run(engine, plan_joint_move(q, goal, speed=1.0))
        assert r.final_error_rad <= FINAL_MAX_RAD
        assert r.rms_tracking_error_rad <= RMS_MAX_RAD
        q = goal


def test_the_arm_holds_still_against_gravity(engine: SimEngine):
    q = standard_configurations()["outer"]
    engine.set_joints(q)
    engine.advance(1.0)
    s = engine.arm_state()
    assert np.abs(s.q - q).max() < 1e-4
    assert np.abs(s.qd).max() < 1e-3
    # Gravity is carried by the motors (the shoulder most of all).
    tau = engine.controller.last_tau
    assert abs(tau[1]) > 50.0 and abs(tau[1]) > abs(tau[4])


def test_controlled_stop_decelerates_within_the_limits(engine: SimEngine):
    cfg = standard_configurations()
    engine.set_joints(cfg["home"])
    traj = plan_joint_move(cfg["home"], cfg["table"], speed=1.0)
    reports = []
    engine.start_move(traj, reports.append)
    engine.advance(0.5 * traj.duration_s)
    v_before = np.abs(engine.arm_state().qd).max()
    assert v_before > 0.3
    engine.stop_motion()
    engine.advance(1.5)
    (r,) = reports
    assert r.reason == "stopped" and not r.completed
    s = engine.arm_state()
    assert np.abs(s.qd).max() < 2e-3
    assert r.final_error_rad > 0.1  # stopped well short of the goal


def test_stop_trajectory_respects_acceleration_limits():
    v0 = np.array([1.0, -0.5, 0.2, 0.0, 2.0])
    a = np.asarray(ASEA.max_acceleration_rad_s2)
    t = stop_trajectory(np.zeros(5), v0, a)
    assert t.duration_s == pytest.approx(np.max(np.abs(v0) / a))
    np.testing.assert_allclose(t.qd[-1], 0.0)
    acc = np.diff(t.qd, axis=0) / np.diff(t.t_s)[:, None]
    assert np.all(np.abs(acc) <= a * (1 + 1e-9))
    np.testing.assert_allclose(t.q[-1], v0 * np.abs(v0) / (2 * a), atol=1e-12)


def test_brake_holds_at_once(engine: SimEngine):
    cfg = standard_configurations()
    engine.set_joints(cfg["home"])
    traj = plan_joint_move(cfg["home"], cfg["top"], speed=1.0)
    reports = []
    engine.start_move(traj, reports.append)
    engine.advance(0.4 * traj.duration_s)
    q_brake = engine.arm_state().q
    engine.brake()
    assert reports and reports[0].reason == "estop"  # the move ends at once
    engine.advance(1.0)
    s = engine.arm_state()
    assert np.abs(s.qd).max() < 1e-3
    assert np.abs(s.q - q_brake).max() < 0.05  # braked within a few centimetres of travel
    engine.clear_estop()


def test_pd_gravity_baseline_tracks_worse_than_computed_torque():
    rms = {}
    for law in ("computed_torque", "pd_gravity"):
        e = SimEngine(SimConfig(gains=ControllerGains(law=law)))
        try:
            _, traj = standard_moves()[0]
            rms[law] = _run(e, traj).rms_tracking_error_rad
        finally:
            e.stop()
    assert rms["computed_torque"] < 0.5 * rms["pd_gravity"]
    with pytest.raises(ValueError, match="law"):
        ControllerGains(law="bang-bang")
