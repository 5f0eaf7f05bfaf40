import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from robot.errors import OrientationNotAchievable, OutOfReach
from robot.kinematics import R_base_ee, T_base_ee, ik_pose
from robot.kinematics.pose6 import rotation_angle
from robot.model import ASEA

_q = st.tuples(*[st.floats(float(lo), float(hi)) for lo, hi in ASEA.joint_limits_rad]).map(np.array)


def _rot(axis, angle):
    k = np.asarray(axis, dtype=float)
    k = k / np.linalg.norm(k)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


@settings(max_examples=200, deadline=None)
@given(_q)
def test_reachable_6dof_targets_are_met_exactly(q):
    r = ik_pose(T_base_ee(q), seed=q)
    np.testing.assert_allclose(r.q, q, atol=1e-9)
    assert r.position_error_m < 1e-12
    assert r.orientation_error_rad < 1e-9
    np.testing.assert_allclose(r.R_residual, np.eye(3), atol=1e-9)


def test_residual_is_the_tilt_out_of_the_arm_plane_and_minimal():
    q = ASEA.q_ready.copy()
    q[4] = 0.4
    T = T_base_ee(q)
    # Tilt the approach axis out of the vertical plane x-z (the arm plane at q1 = 0).
    for angle in (0.01, 0.1, 0.3):
        Tt = T.copy()
        Tt[:3, :3] = _rot((1.0, 0.2, 0.0), angle) @ T[:3, :3]
        r = ik_pose(Tt, max_orientation_error_rad=math.pi)
        out_of_plane = math.asin(abs(Tt[1, 2]))
        assert r.orientation_error_rad == pytest.approx(out_of_plane, abs=1e-12)
        np.testing.assert_allclose(r.R_residual @ r.T_base_ee[:3, :3], Tt[:3, :3], atol=1e-12)
        assert r.position_error_m < 1e-12
        # No reachable orientation at that position is closer (dense grid over phi, roll).
        phi, psi = np.meshgrid(np.linspace(-np.pi, np.pi, 361), np.linspace(-np.pi, np.pi, 361))
        qq = np.zeros((phi.size, 5))
        qq[:, 1], qq[:, 4] = phi.ravel(), psi.ravel()
        tr = np.einsum("ij,nij->n", Tt[:3, :3], R_base_ee(qq))
        grid_best = math.acos(min(1.0, (tr.max() - 1) / 2))
        assert r.orientation_error_rad <= grid_best + 1e-12


def test_orientation_not_achievable_reports_the_residual():
    T = T_base_ee(ASEA.q_ready)
    T[:3, :3] = _rot((1.0, 0.0, 0.0), 0.05) @ T[:3, :3]
    with pytest.raises(OrientationNotAchievable) as e:
        ik_pose(T)
    assert e.value.reason == "orientation"
    assert e.value.residual_rad == pytest.approx(0.05, abs=1e-12)
    assert "orientation not achievable" in str(e.value)
    assert ik_pose(T, max_orientation_error_rad=0.06).orientation_error_rad == pytest.approx(
        0.05, abs=1e-12
    )


def test_out_of_reach_position():
    T = np.eye(4)
    T[:3, 3] = (3.0, 0.0, 1.0)
    with pytest.raises(OutOfReach):
        ik_pose(T, max_orientation_error_rad=math.pi)


@pytest.mark.parametrize(
    "T",
    [np.eye(3), np.diag([1.0, 1.0, 2.0, 1.0]), np.diag([1.0, 1.0, -1.0, 1.0])],
)
def test_bad_transforms_raise_value_error(T):
    with pytest.raises(ValueError, match="T_base_ee_target"):
        ik_pose(T)


def test_rotation_angle_is_accurate_for_tiny_angles():
    assert rotation_angle(_rot((0, 0, 1), 1e-10)) == pytest.approx(1e-10, rel=1e-6)
    assert rotation_angle(_rot((1, 2, 3), 2.5)) == pytest.approx(2.5, abs=1e-12)
