import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from robot.errors import JointLimitError
from robot.model import ASEA
from robot.trajectory import plan_joint_move

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
