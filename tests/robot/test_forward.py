import numpy as np

from robot.kinematics import R_base_ee, T_base_ee, fk, joint_positions
from robot.model import ASEA


def _random_q(n, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(ASEA.lower, ASEA.upper, size=(n, 5))


def test_fk_matches_equation_20_written_out():
    q = _random_q(500)
    L1, L2, L3, L4, L5 = ASEA.link_lengths_m
    q1, q2, q3, q4 = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    r = L2 * np.cos(q2) + L3 * np.cos(q2 + q3) + (L4 + L5) * np.cos(q2 + q3 + q4)
    expected = np.stack(
        [
            np.cos(q1) * r,
            np.sin(q1) * r,
            L2 * np.sin(q2) + L3 * np.sin(q2 + q3) + L1 + (L4 + L5) * np.sin(q2 + q3 + q4),
            np.cos(q2 + q3 + q4),
            np.sin(q2 + q3 + q4),
        ],
        axis=1,
    )
    np.testing.assert_allclose(fk(q), expected, atol=1e-12)
    np.testing.assert_allclose(fk(q[7]), expected[7], atol=1e-12)


def test_full_pose_agrees_with_equation_20():
    q = _random_q(200, seed=1)
    T = T_base_ee(q)
    p = fk(q)
    np.testing.assert_allclose(T[:, :3, 3], p[:, :3], atol=1e-12)
    # The approach axis z_ee projects onto the arm plane as (u, w).
    z = T[:, :3, 2]
    np.testing.assert_allclose(np.hypot(z[:, 0], z[:, 1]), np.abs(p[:, 3]), atol=1e-12)
    np.testing.assert_allclose(z[:, 2], p[:, 4], atol=1e-12)
    R = R_base_ee(q)
    np.testing.assert_allclose(
        R @ np.swapaxes(R, 1, 2), np.broadcast_to(np.eye(3), R.shape), atol=1e-12
    )
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)


def test_q5_rolls_about_the_approach_axis():
    q = _random_q(1, seed=2)[0]
    q2 = q.copy()
    q2[4] += 0.3
    Ta, Tb = T_base_ee(q), T_base_ee(q2)
    np.testing.assert_allclose(Ta[:3, 2], Tb[:3, 2], atol=1e-12)
    cos = float(Ta[:3, 0] @ Tb[:3, 0])
    assert np.isclose(cos, np.cos(0.3))


def test_joint_positions_end_at_the_flange():
    q = _random_q(50, seed=3)
    pts = joint_positions(q)
    np.testing.assert_allclose(pts[:, -1], fk(q)[:, :3], atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(pts[:, 2] - pts[:, 1], axis=1), ASEA.L2, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(pts[:, 3] - pts[:, 2], axis=1), ASEA.L3, atol=1e-12)
