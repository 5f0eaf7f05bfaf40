import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from robot.errors import JointLimitsBlock, OutOfReach, Unreachable
from robot.kinematics import BRANCHES, T_base_ee, fk, ik, ik_batch, ik_solutions
from robot.model import ASEA

_q = st.tuples(*[st.floats(float(lo), float(hi)) for lo, hi in ASEA.joint_limits_rad]).map(np.array)

# Every joint free over a full turn: all four branches exist for every reachable pose.
WIDE = replace(ASEA, joint_limits_rad=np.tile([-math.pi, math.pi], (5, 1)))
_q_wide = st.tuples(*[st.floats(-math.pi, math.pi) for _ in range(5)]).map(np.array)


def _angle_diff(a, b):
    return np.abs(np.angle(np.exp(1j * (np.asarray(a) - np.asarray(b)))))


@settings(max_examples=300, deadline=None)
@given(_q)
def test_round_trip_across_the_joint_space(q):
    pose = fk(q)
    sols = ik_solutions(pose, roll=q[4])
    inside = [s for s in sols if s.within_limits]
    assert inside, "the configuration that produced the pose must be found"
    for s in inside:
        assert ASEA.within_limits(s.q)
        np.testing.assert_allclose(fk(s.q), pose, atol=1e-9)
        np.testing.assert_allclose(T_base_ee(s.q), T_base_ee(q), atol=1e-9)
    assert any(np.all(_angle_diff(s.q, q) < 1e-9) for s in inside)
    # ik picks the branch within limits nearest the seed: the original itself.
    np.testing.assert_allclose(ik(pose, roll=q[4], seed=q), q, atol=1e-9)


@settings(max_examples=300, deadline=None)
@given(_q_wide)
def test_every_branch_reproduces_the_flange_pose(q):
    T = T_base_ee(q)
    r = (
        WIDE.L2 * math.cos(q[1])
        + WIDE.L3 * math.cos(q[1] + q[2])
        + WIDE.L45 * math.cos(q[1] + q[2] + q[3])
    )
    if abs(r) < 1e-6:  # the flange on the q1 axis: the arm plane is taken from the seed
        return
    p = T[:3, 3]
    # The pose of the physical flange: u is the approach's outward horizontal component.
    theta = math.atan2(p[1], p[0])
    u = T[0, 2] * math.cos(theta) + T[1, 2] * math.sin(theta)
    roll = q[4] if r > 0 else q[4] - math.pi
    sols = ik_solutions((*p, u, T[2, 2]), roll=roll, model=WIDE)
    assert [s.branch for s in sols] == list(BRANCHES)
    for s in sols:
        np.testing.assert_allclose(T_base_ee(s.q), T, atol=1e-9)
    # At full stretch (q3 = 0 or pi) acos amplifies the rounding of cos q3 to ~1e-8 rad.
    tol = 1e-8 if abs(math.sin(q[2])) > 1e-6 else 1e-7
    assert any(np.all(_angle_diff(s.q, q) < tol) for s in sols)
    # Front branches reproduce eq. 20 as written; reach-over ones report -u.
    for s in sols:
        sign = 1.0 if s.branch.startswith("front") else -1.0
        np.testing.assert_allclose(fk(s.q)[3], sign * u, atol=1e-9)


def test_q_ready_and_q_home_are_recovered():
    for q in (ASEA.q_ready, ASEA.q_home):
        np.testing.assert_allclose(ik(fk(q), roll=q[4]), q, atol=1e-12)


def test_only_the_front_elbow_up_branch_fits_the_asea_ranges():
    sols = ik_solutions(fk(ASEA.q_ready))
    assert [s.within_limits for s in sols] == [True, False, False, False]
    assert sols[0].violated_joints == () and sols[0].detail == ""
    for s in sols[1:]:
        assert s.violated_joints and all(f"q{j}" in s.detail for j in s.violated_joints)
    d = sols[1].as_dict()
    assert set(d) >= {"joints", "within_limits", "branch"} and len(d["joints"]) == 5


def test_out_of_reach_gives_the_distance():
    with pytest.raises(OutOfReach) as e:
        ik((2.0, 0.0, 1.0, 1.0, 0.0))
    assert isinstance(e.value, Unreachable) and e.value.code == "unreachable"
    assert e.value.reason == "out_of_reach"
    msg = str(e.value)
    # Wrist centre at (2 - 0.093, 1 - 0.73) from the shoulder.
    dist = math.hypot(2.0 - ASEA.L45, 1.0 - ASEA.L1)
    assert f"{dist:.4f} m from the shoulder" in msg
    assert f"by {dist - (ASEA.L2 + ASEA.L3):.4g} m" in msg
    with pytest.raises(OutOfReach):
        ik_solutions((2.0, 0.0, 1.0, 1.0, 0.0))


def test_joint_limit_names_the_blocking_joint():
    # Tool pointing straight up right above the station: needs q4 beyond its 58.5 deg end.
    with pytest.raises(JointLimitsBlock) as e:
        ik((0.8, 0.0, 1.0, 0.0, 1.0))
    assert e.value.reason == "joint_limit"
    assert "no solution within the joint limits" in str(e.value)
    assert 4 in e.value.joints or "q4" in str(e.value)


def test_roll_outside_the_q5_range_is_blocked_by_q5():
    with pytest.raises(JointLimitsBlock) as e:
        ik(fk(ASEA.q_ready), roll=math.radians(175.0))
    assert "q5 = 175.00 deg outside [-165.75, 165.75] deg" in str(e.value)


def test_roll_wraps_into_the_q5_range():
    q = ik(fk(ASEA.q_ready), roll=2 * math.pi + 0.3)
    assert q[4] == pytest.approx(0.3, abs=1e-12)
    q = ik(fk(ASEA.q_ready), roll=-2 * math.pi - 2.5)
    assert q[4] == pytest.approx(-2.5, abs=1e-12)


def test_target_on_the_q1_axis_takes_q1_from_the_seed():
    # On the ASEA the flange never reaches the axis; with wide ranges it does.
    q = np.array([0.7, 1.2, -2.4, 0.5, 0.1])
    pose = fk(q, WIDE)
    r = (
        WIDE.L2 * math.cos(q[1])
        + WIDE.L3 * math.cos(q[1] + q[2])
        + WIDE.L45 * math.cos(q[1] + q[2] + q[3])
    )
    # Move the target onto the axis by shifting it horizontally.
    axis_pose = (0.0, 0.0, pose[2], math.cos(q[1] + q[2] + q[3]), pose[4])
    for seed_q1 in (0.7, -2.0):
        seed = np.array([seed_q1, 1.2, -2.4, 0.5, 0.1])
        sol = ik(axis_pose, roll=0.1, seed=seed, model=WIDE)
        assert np.all(np.abs(fk(sol, WIDE)[:3] - axis_pose[:3]) < 1e-9)
        assert min(_angle_diff(sol[0], seed_q1), _angle_diff(sol[0], seed_q1 + math.pi)) < 1e-12
    assert abs(r) > 0  # the original was off the axis: the test moved it


def test_q1_at_the_range_end_takes_the_representative_nearest_the_seed():
    q = np.array(ASEA.q_ready)
    q[0] = math.pi
    pose = fk(q)
    assert ik(pose, seed=np.r_[3.0, ASEA.q_ready[1:]])[0] == pytest.approx(math.pi)
    assert ik(pose, seed=np.r_[-3.0, ASEA.q_ready[1:]])[0] == pytest.approx(-math.pi)


@pytest.mark.parametrize(
    "pose",
    [(0.8, 0.0, 1.0, 0.0, 0.9), (0.8, 0.0, 1.0, 1.0), "abc", (0.8, np.nan, 1.0, 0.0, -1.0)],
)
def test_bad_poses_raise_value_error(pose):
    with pytest.raises(ValueError, match="pose") as e:
        ik(pose)
    assert not isinstance(e.value, Unreachable)


def test_bad_roll_and_seed_raise_value_error():
    with pytest.raises(ValueError, match="roll"):
        ik(fk(ASEA.q_ready), roll=float("inf"))
    with pytest.raises(ValueError, match="seed"):
        ik(fk(ASEA.q_ready), seed=[0.0, 1.0])


def test_batch_equals_scalar_including_failures():
    rng = np.random.default_rng(7)
    n = 3000
    a = rng.uniform(-math.pi, math.pi, n)
    poses = np.column_stack(
        [rng.uniform(-1.6, 1.6, (n, 2)), rng.uniform(-0.4, 2.2, n), np.cos(a), np.sin(a)]
    )
    poses[:1000] = fk(rng.uniform(ASEA.lower, ASEA.upper, (1000, 5)))
    rolls = rng.uniform(-4.0, 4.0, n)
    rolls[:1000] = rng.uniform(ASEA.lower[4], ASEA.upper[4], 1000)
    seeds = rng.uniform(ASEA.lower, ASEA.upper, (n, 5))
    q, ok = ik_batch(poses, rolls, seed=seeds)
    assert ok[:1000].all() and 0 < ok[1000:].sum() < n - 1000
    for i in range(n):
        try:
            qs = ik(poses[i], roll=rolls[i], seed=seeds[i])
        except Unreachable:
            assert not ok[i] and np.isnan(q[i]).all()
        else:
            assert ok[i]
            np.testing.assert_allclose(q[i], qs, atol=1e-12)


def test_batch_round_trip_to_1e_9_m():
    rng = np.random.default_rng(3)
    q = rng.uniform(ASEA.lower, ASEA.upper, (20000, 5))
    p = fk(q)
    qi, ok = ik_batch(p, q[:, 4])
    assert ok.all()
    assert np.abs(fk(qi)[:, :3] - p[:, :3]).max() <= 1e-9
    assert np.abs(fk(qi)[:, 3:] - p[:, 3:]).max() <= 1e-9
    np.testing.assert_allclose(qi, q, atol=1e-9)


def test_batch_rejects_bad_input():
    with pytest.raises(ValueError, match="shape"):
        ik_batch(np.zeros((3, 4)))
    bad = np.tile(fk(ASEA.q_ready), (3, 1))
    bad[2, 3] = 0.5
    with pytest.raises(ValueError, match="row 2"):
        ik_batch(bad)
    with pytest.raises(ValueError, match="seed"):
        ik_batch(fk(ASEA.q_ready)[None], seed=np.zeros((2, 5)))
