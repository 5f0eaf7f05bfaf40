"""Bug: the planners built tables whose size grew with 1/speed (24 GB at speed 1e-6).

Every planner now refuses, before allocating anything, a plan longer than
``MAX_DURATION_S`` or with more than ``MAX_SAMPLES`` samples, and a speed below ``MIN_SPEED``.
"""

from __future__ import annotations

import numpy as np
import pytest

from robot.errors import TrajectoryTooLong
from robot.kinematics import fk
from robot.model import ASEA
from robot.trajectory import (
    MAX_DURATION_S,
    MAX_SAMPLES,
    MIN_SPEED,
    JointTrajectory,
    check_plan_size,
    plan_joint_move,
    sample_at_rate,
)
from robot.trajectory_cartesian import plan_cartesian_line


@pytest.mark.parametrize("speed", [1e-6, 1e-8, 1e-300, 0.0, MIN_SPEED / 2, True])
@pytest.mark.parametrize("profile", ["trapezoid", "quintic"])
def test_speed_below_the_floor_is_refused(speed, profile):
    with pytest.raises(ValueError, match=r"speed must be in \[0.01, 1\]"):
        plan_joint_move(ASEA.q_home, ASEA.q_ready, speed=speed, profile=profile)


@pytest.mark.parametrize("profile", ["trapezoid", "quintic"])
def test_longest_move_at_the_floor_stays_within_the_bounds(profile):
    tr = plan_joint_move(ASEA.lower, ASEA.upper, speed=MIN_SPEED, profile=profile)
    assert tr.duration_s <= MAX_DURATION_S and tr.t_s.size <= MAX_SAMPLES


def test_too_many_samples_are_refused_before_allocation():
    # Valid speed and rate, but 3.6e3 s x 2000 Hz samples: refused by the sample bound.
    with pytest.raises(TrajectoryTooLong, match="samples") as info:
        plan_joint_move(ASEA.lower, ASEA.upper, speed=MIN_SPEED, rate_hz=2000.0)
    assert info.value.samples > MAX_SAMPLES and info.value.code == "trajectory_too_long"


def test_cartesian_line_and_resampling_respect_the_bounds():
    goal = fk(ASEA.q_ready)
    with pytest.raises(ValueError, match="speed must be in"):
        plan_cartesian_line(ASEA.q_home, goal, speed=1e-6)
    tr = plan_cartesian_line(ASEA.q_home, goal, speed=MIN_SPEED)
    assert tr.duration_s <= MAX_DURATION_S
    # A valid table of 3000 s resampled at 1 kHz would hold 3e6 samples.
    long = JointTrajectory(np.array([0.0, 3000.0]), np.zeros((2, 5)), np.zeros((2, 5)))
    with pytest.raises(TrajectoryTooLong, match="samples"):
        sample_at_rate(long, 1000.0)
    with pytest.raises(ValueError, match="rate_hz must be in"):
        sample_at_rate(tr, 1e9)


def test_check_plan_size_states_the_bounds():
    assert check_plan_size(1.0, 100.0) == 101
    for T in (MAX_DURATION_S * 1.01, float("inf"), float("nan")):
        with pytest.raises(TrajectoryTooLong, match="more than"):
            check_plan_size(T, 100.0)


def test_a_table_over_the_bounds_cannot_be_built():
    n = MAX_SAMPLES + 1
    t = np.arange(n, dtype=np.float64) * 1e-3
    q = np.zeros((n, 5))
    with pytest.raises(TrajectoryTooLong):
        JointTrajectory(t, q, q)
