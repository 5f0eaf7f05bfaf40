import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from robot.errors import JointLimitError
from robot.model import ASEA
from robot.trajectory import JointTrajectory, plan_joint_move, sample_at_rate

_q = st.tuples(*[st.floats(float(lo), float(hi)) for lo, hi in ASEA.joint_limits_rad]).map(np.array)


@settings(max_examples=150, deadline=None)
@given(_q, _q, st.floats(0.05, 1.0))
def test_joint_move_respects_limits_and_arrives(qa, qb, speed):
    tr = plan_joint_move(qa, qb, speed=speed, rate_hz=200.0)
    assert ASEA.within_limits(tr.q).all()
    np.testing.assert_allclose(tr.q[0], qa, atol=1e-12)
    np.testing.assert_allclose(tr.q[-1], qb, atol=1e-12)
    assert np.all(np.abs(tr.qd) <= ASEA.max_velocity_rad_s * speed * (1 + 1e-9))
    if tr.t_s.size > 2:
        acc = np.diff(tr.qd[:-1], axis=0) / np.diff(tr.t_s[:-1])[:, None]
        # Finite differences of a trapezoid overshoot by at most one sample's worth.
        assert np.all(np.abs(acc) <= ASEA.max_acceleration_rad_s2 * speed**2 * 1.01 + 1e-6)


def test_joint_move_is_synchronised():
    tr = plan_joint_move(ASEA.q_home, ASEA.q_ready)
    s = (tr.q - tr.q[0]) / (tr.q[-1] - tr.q[0] + 1e-300)
    moving = np.abs(tr.q[-1] - tr.q[0]) > 1e-9
    spread = np.ptp(s[:, moving], axis=1)
    assert spread.max() < 1e-9


def test_joint_move_refuses_targets_outside_limits():
    goal = np.array(ASEA.q_home)
    goal[1] = np.radians(20.0)
    with pytest.raises(JointLimitError, match="q2"):
        plan_joint_move(ASEA.q_home, goal)


@pytest.mark.parametrize("speed", [0.0, -0.5, 1.5, float("nan")])
def test_joint_move_rejects_bad_speed(speed):
    with pytest.raises(ValueError, match="speed"):
        plan_joint_move(ASEA.q_home, ASEA.q_ready, speed=speed)


@settings(max_examples=150, deadline=None)
@given(_q, _q, st.floats(0.05, 1.0))
def test_quintic_move_respects_limits_and_arrives(qa, qb, speed):
    tr = plan_joint_move(qa, qb, speed=speed, rate_hz=200.0, profile="quintic")
    assert ASEA.within_limits(tr.q).all()
    np.testing.assert_allclose(tr.q[0], qa, atol=1e-12)
    np.testing.assert_allclose(tr.q[-1], qb, atol=1e-12)
    assert np.all(np.abs(tr.qd) <= ASEA.max_velocity_rad_s * speed * (1 + 1e-9))
    assert np.all(np.abs(tr.qdd) <= ASEA.max_acceleration_rad_s2 * speed**2 * (1 + 1e-9))
    # Smooth: zero velocity and acceleration at both ends.
    np.testing.assert_allclose(tr.qd[[0, -1]], 0.0, atol=1e-12)
    np.testing.assert_allclose(tr.qdd[[0, -1]], 0.0, atol=1e-9)


def test_quintic_tables_are_consistent_derivatives():
    tr = plan_joint_move(ASEA.q_home, ASEA.q_ready, profile="quintic", rate_hz=1000.0)
    qd_num = np.gradient(tr.q, tr.t_s, axis=0)
    qdd_num = np.gradient(tr.qd, tr.t_s, axis=0)
    assert np.abs(qd_num - tr.qd)[1:-1].max() < 1e-4
    assert np.abs(qdd_num - tr.qdd)[1:-1].max() < 1e-2
    # One joint reaches its speed or acceleration limit (the profile is not padded).
    ratio = max(
        (np.abs(tr.qd) / ASEA.max_velocity_rad_s).max(),
        (np.abs(tr.qdd) / ASEA.max_acceleration_rad_s2).max(),
    )
    assert ratio == pytest.approx(1.0, abs=1e-3)


def test_trapezoid_accelerations_are_the_blend_values():
    tr = plan_joint_move(ASEA.q_home, ASEA.q_ready)
    j = int(np.argmax(np.abs(tr.q[-1] - tr.q[0])))
    a = np.abs(tr.qdd[:, j])
    assert a.max() <= ASEA.max_acceleration_rad_s2[j] * (1 + 1e-9)
    assert set(np.round(np.unique(a) / a.max(), 9)) <= {0.0, 1.0}


def test_quintic_is_not_slower_than_needed_and_unknown_profile_refused():
    tq = plan_joint_move(ASEA.q_home, ASEA.q_ready, profile="quintic").duration_s
    tt = plan_joint_move(ASEA.q_home, ASEA.q_ready).duration_s
    assert tt < tq < 1.6 * tt
    with pytest.raises(ValueError, match="profile"):
        plan_joint_move(ASEA.q_home, ASEA.q_ready, profile="cubic")


def test_trajectory_estimates_missing_accelerations_and_copies_inputs():
    t = np.linspace(0.0, 1.0, 11)
    q = np.tile(ASEA.q_home, (11, 1))
    qd = np.zeros((11, 5))
    qd[:, 0] = 2.0 * t
    tr = JointTrajectory(t, q, qd)
    np.testing.assert_allclose(tr.qdd[:, 0], 2.0, atol=1e-12)
    assert q.flags.writeable  # the caller's arrays are left alone
    with pytest.raises(ValueError, match="qdd"):
        JointTrajectory(t, q, qd, np.zeros((3, 5)))


@settings(max_examples=60, deadline=None)
@given(_q, _q, st.floats(1.0, 500.0))
def test_sample_at_rate_gives_a_fixed_period_within_limits(qa, qb, rate):
    tr = plan_joint_move(qa, qb, profile="quintic")
    s = sample_at_rate(tr, rate)
    assert s.t_s[0] == 0.0 and s.t_s[-1] == pytest.approx(tr.duration_s, abs=1e-12)
    if s.t_s.size > 2:
        np.testing.assert_allclose(np.diff(s.t_s[:-1]), 1.0 / rate, rtol=1e-9)
        assert 0 < s.t_s[-1] - s.t_s[-2] <= 1.0 / rate * (1 + 1e-9)
    assert ASEA.within_limits(s.q).all()
    np.testing.assert_allclose(s.q[[0, -1]], tr.q[[0, -1]], atol=1e-12)
    assert np.all(np.abs(s.qd) <= ASEA.max_velocity_rad_s * (1 + 1e-9))
    assert np.all(np.abs(s.qdd) <= ASEA.max_acceleration_rad_s2 * (1 + 1e-9))


def test_sample_at_rate_refuses_bad_rates_and_out_of_range_tables():
    tr = plan_joint_move(ASEA.q_home, ASEA.q_ready)
    with pytest.raises(ValueError, match="rate_hz"):
        sample_at_rate(tr, 0.0)
    q = np.tile(ASEA.q_home, (2, 1))
    q[1, 1] = 3.0
    with pytest.raises(JointLimitError, match="q2"):
        sample_at_rate(JointTrajectory(np.array([0.0, 1.0]), q, np.zeros((2, 5))), 10.0)
