import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from robot.errors import JointLimitError, JointLimitsBlock, OutOfReach, Unreachable
from robot.kinematics import fk
from robot.model import ASEA
from robot.trajectory_cartesian import plan_cartesian_line

_q = st.tuples(*[st.floats(float(lo), float(hi)) for lo, hi in ASEA.joint_limits_rad]).map(np.array)
_delta = st.tuples(*[st.floats(-0.4, 0.4) for _ in range(5)]).map(np.array)


def _distance_to_segment(P, a, b):
    d = b - a
    t = np.clip((P - a) @ d / max(d @ d, 1e-300), 0.0, 1.0)
    return np.linalg.norm(P - (a + t[:, None] * d), axis=1)


def _check_line(tr, q0, goal, roll, speed=1.0):
    assert ASEA.within_limits(tr.q).all()
    np.testing.assert_array_equal(tr.q[0], q0)
    np.testing.assert_allclose(fk(tr.q[-1]), goal, atol=1e-9)
    assert math.cos(tr.q[-1][4] - roll) == pytest.approx(1.0, abs=1e-12)
    p = fk(tr.q)
    assert _distance_to_segment(p[:, :3], fk(q0)[:3], np.array(goal[:3])).max() < 1e-9
    assert np.all(np.abs(tr.qd) <= ASEA.max_velocity_rad_s * speed * (1 + 1e-9))
    assert np.all(np.abs(tr.qdd) <= ASEA.max_acceleration_rad_s2 * speed**2 * (1 + 1e-9))


@settings(max_examples=60, deadline=None)
@given(_q, _delta, st.floats(0.1, 1.0))
def test_cartesian_lines_stay_within_every_limit(q0, dq, speed):
    q1 = np.clip(q0 + dq, ASEA.lower, ASEA.upper)
    goal = tuple(fk(q1))
    try:
        tr = plan_cartesian_line(q0, goal, roll=q1[4], speed=speed, rate_hz=100.0)
    except Unreachable as e:  # a straight line between two reachable poses may leave the
        assert "% of the path" in str(e)  # workspace: then it says where
        return
    _check_line(tr, q0, goal, q1[4], speed)


def test_a_line_over_the_station_is_straight_and_timed_by_its_derivatives():
    goal = (0.65, 0.25, 0.95, math.cos(-1.2), math.sin(-1.2))
    tr = plan_cartesian_line(ASEA.q_ready, goal, roll=0.4, rate_hz=500.0)
    _check_line(tr, ASEA.q_ready, goal, 0.4)
    qd_num = np.gradient(tr.q, tr.t_s, axis=0)
    assert np.abs(qd_num - tr.qd)[1:-1].max() < 2e-3
    # The flange speed stays below the Cartesian limit (0.25 m/s by default).
    v = np.linalg.norm(np.gradient(fk(tr.q)[:, :3], tr.t_s, axis=0), axis=1)
    assert v.max() <= 0.25 * (1 + 1e-3)
    assert plan_cartesian_line(ASEA.q_ready, goal, roll=0.4, speed=0.5).duration_s > tr.duration_s


def test_joint_limits_stretch_the_duration():
    goal = (0.65, 0.25, 0.95, math.cos(-1.2), math.sin(-1.2))
    slow = replace(ASEA, max_velocity_rad_s=ASEA.max_velocity_rad_s / 20)
    fast = plan_cartesian_line(ASEA.q_ready, goal)
    tr = plan_cartesian_line(ASEA.q_ready, goal, model=slow)
    assert tr.duration_s > 3 * fast.duration_s
    assert np.abs(tr.qd / slow.max_velocity_rad_s).max() == pytest.approx(1.0, abs=0.02)


def test_zero_length_move_is_a_single_sample():
    tr = plan_cartesian_line(ASEA.q_ready, fk(ASEA.q_ready))
    assert tr.t_s.size == 1 and tr.duration_s == 0.0


def test_goal_out_of_reach_is_reported():
    with pytest.raises(OutOfReach, match="goal of the Cartesian line"):
        plan_cartesian_line(ASEA.q_ready, (2.5, 0.0, 1.0, 1.0, 0.0))


def test_blocked_path_names_where():
    # Straight across the column at the station height: the middle is too close to reach.
    with pytest.raises(JointLimitsBlock) as e:
        plan_cartesian_line(ASEA.q_ready, (-0.8, 0.0, 1.0, 0.0, -1.0))
    msg = str(e.value)
    assert "Cartesian line blocked at" in msg and "% of the path" in msg and "q3" in msg


def test_crossing_the_q1_range_end_is_a_discontinuity():
    q0 = ASEA.q_ready.copy()
    q0[0] = math.radians(170.0)
    q1 = ASEA.q_ready.copy()
    q1[0] = math.radians(-170.0)
    with pytest.raises(Unreachable, match="not continuous in joint space") as e:
        plan_cartesian_line(q0, fk(q1))
    assert "q1 jumps" in str(e.value)


def test_crossing_the_q1_axis_is_refused():
    wide = replace(ASEA, joint_limits_rad=np.tile([-math.pi, math.pi], (5, 1)))
    q0 = np.array([0.0, 1.2, -2.2, -0.6, 0.0])
    p = fk(q0, wide)
    goal = (-p[0], 0.0, p[2], p[3], p[4])
    with pytest.raises(Unreachable) as e:
        plan_cartesian_line(q0, goal, model=wide)
    assert "path" in str(e.value)


def test_bad_inputs():
    with pytest.raises(JointLimitError):
        plan_cartesian_line(np.zeros(5), fk(ASEA.q_ready))
    with pytest.raises(ValueError, match="pose"):
        plan_cartesian_line(ASEA.q_ready, (0.8, 0.0, 1.0, 0.3, 0.3))
    with pytest.raises(ValueError, match="max_linear_speed_m_s"):
        plan_cartesian_line(ASEA.q_ready, fk(ASEA.q_home), max_linear_speed_m_s=0.0)
    with pytest.raises(ValueError, match="speed"):
        plan_cartesian_line(ASEA.q_ready, fk(ASEA.q_home), speed=2.0)
