"""The generated MJCF reproduces the arm of robot.model and eq. 20 exactly."""

from __future__ import annotations

import dataclasses
import math

import mujoco
import numpy as np
import pytest

from robot.kinematics import T_base_ee, joint_positions
from robot.model import ASEA
from robot.sim import SimConfig, build_cell
from robot.sim.mjcf import CHAIN_SITES, JOINT_NAMES


def _flange(m: mujoco.MjModel, d: mujoco.MjData) -> np.ndarray:
    fid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "flange")
    T = np.eye(4)
    T[:3, :3] = d.xmat[fid].reshape(3, 3)
    T[:3, 3] = d.xpos[fid]
    return T


def _check_chain(m: mujoco.MjModel, model, qs: np.ndarray) -> None:
    d = mujoco.MjData(m)
    for q in qs:
        d.qpos[:] = q
        mujoco.mj_kinematics(m, d)
        np.testing.assert_allclose(_flange(m, d), T_base_ee(q, model), atol=1e-9)
        pts = joint_positions(q, model)
        for i, site in enumerate(CHAIN_SITES):
            sid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, site)
            np.testing.assert_allclose(d.site_xpos[sid], pts[i + 1], atol=1e-9)


def test_flange_frame_is_T_base_ee_on_random_configurations(engine):
    rng = np.random.default_rng(1)
    qs = rng.uniform(ASEA.lower, ASEA.upper, size=(200, 5))
    _check_chain(engine.model, ASEA, qs)


def test_model_is_generated_from_the_arm_constants():
    # A different arm (longer links, other ranges) yields a model that follows it, so no
    # constant of ASEA is copied into the MJCF by hand.
    other = dataclasses.replace(ASEA, link_lengths_m=(0.5, 0.8, 0.6, 0.1, 0.05))
    m = build_cell(SimConfig(), other).compile()
    rng = np.random.default_rng(2)
    _check_chain(m, other, rng.uniform(other.lower, other.upper, size=(30, 5)))
    for i, name in enumerate(JOINT_NAMES):
        jid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name)
        lo, hi = m.jnt_range[jid]
        assert lo < other.lower[i] and hi > other.upper[i]  # hard stops outside the soft range


@pytest.mark.parametrize("joint", range(5))
def test_joint_signs_follow_eq_20(engine, joint):
    m = engine.model
    d = mujoco.MjData(m)
    q = np.array(ASEA.q_ready)
    d.qpos[:] = q
    mujoco.mj_kinematics(m, d)
    before = _flange(m, d)
    q2 = q.copy()
    q2[joint] += 0.01
    d.qpos[:] = q2
    mujoco.mj_kinematics(m, d)
    np.testing.assert_allclose(_flange(m, d), T_base_ee(q2), atol=1e-9)
    if joint == 1:  # a positive shoulder angle raises the flange (z = ... + L2 sin q2)
        assert _flange(m, d)[2, 3] > before[2, 3]


def test_arm_is_torque_driven_with_plausible_dynamics(engine):
    m = engine.model
    assert m.opt.timestep <= 1.0 / 500.0  # controller and physics at >= 500 Hz
    assert m.nu == 5
    for i in range(5):
        assert m.actuator_gaintype[i] == mujoco.mjtGain.mjGAIN_FIXED
        assert m.actuator_biastype[i] == mujoco.mjtBias.mjBIAS_NONE  # a plain motor: torque in
        assert m.actuator_gear[i, 0] == 1.0
    masses = [
        m.body_mass[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, b)]
        for b in ("column", "upper_arm", "forearm", "wrist", "flange")
    ]
    assert all(mass > 0.5 for mass in masses)
    assert sum(masses) > 40.0  # an industrial arm, not a toy
    d = mujoco.MjData(m)
    d.qpos[:] = ASEA.q_home
    mujoco.mj_forward(m, d)
    # Gravity loads the shoulder more than the wrist.
    assert abs(d.qfrc_bias[1]) > abs(d.qfrc_bias[3]) > 0.0


def test_camera_is_mounted_at_T_ee_cam(engine):
    m = engine.model
    d = mujoco.MjData(m)
    cam = engine.config.camera
    cid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_CAMERA, "eye")
    for q in np.random.default_rng(3).uniform(ASEA.lower, ASEA.upper, size=(20, 5)):
        d.qpos[:] = q
        mujoco.mj_kinematics(m, d)
        mujoco.mj_camlight(m, d)
        T_cv = cam.T_base_cam(q)
        # MuJoCo's camera looks along its -z with y up: same centre, y and z flipped.
        np.testing.assert_allclose(d.cam_xpos[cid], T_cv[:3, 3], atol=1e-9)
        np.testing.assert_allclose(
            d.cam_xmat[cid].reshape(3, 3), T_cv[:3, :3] @ np.diag([1, -1, -1]), atol=1e-9
        )
    # The mounting is documented as 50 mm off the axis, 40 mm past the flange, tilted ~3 deg.
    T = cam.T_ee_cam
    assert np.linalg.norm(T[:3, 3] - (0.05, 0.0, 0.04)) < 1e-12
    tilt = math.degrees(math.acos(T[2, 2]))
    assert 2.0 < tilt < 5.0
