"""Regression: the pipe flange and both bracket bases could not be picked: the camera and
cup were one 90 mm sphere that hit the belt whenever the cup went down to a low sealing
patch.  The tool is now capsules round the camera and the cup's tube, and the flange's roll
turns the camera away from the part over an off-centre grasp point."""

from __future__ import annotations

import math

import numpy as np
import pytest

from robot.collision import DEFAULT_TOOL_CAPSULES
from robot.kinematics import T_base_ee
from robot.model import ASEA
from robot.pick import plan_pick_place
from robot.sim import CATALOGUE, suction_point
from robot.sim.obstacles import collision_world
from robot.sim.world import WorldLayout

LAYOUT = WorldLayout()
WORLD = collision_world(LAYOUT)


def _gap_to_part(name: str, T_obj: np.ndarray, trajs: list) -> float:
    """Smallest distance from the tool capsules to the part's mesh vertices (truth)."""
    v = np.concatenate(
        [np.asarray(p.mesh.vertices, float) for p in CATALOGUE[name].geometry().pieces]
    )
    v = v @ T_obj[:3, :3].T + T_obj[:3, 3]
    best = math.inf
    for traj in trajs:
        for q in traj.q[:: max(1, len(traj.q) // 25)]:
            T = T_base_ee(q)
            for cap in DEFAULT_TOOL_CAPSULES:
                a = T[:3, :3] @ np.asarray(cap.a_ee) + T[:3, 3]
                b = T[:3, :3] @ np.asarray(cap.b_ee) + T[:3, 3]
                t = np.clip(((v - a) @ (b - a)) / float((b - a) @ (b - a)), 0.0, 1.0)
                best = min(
                    best,
                    float(
                        (
                            np.linalg.norm(v - (a + t[:, None] * (b - a)), axis=1) - cap.radius_m
                        ).min()
                    ),
                )
    return best


@pytest.mark.parametrize("name", ["pipe-flange", "bracket-upright", "bracket-flat"])
@pytest.mark.parametrize("yaw_deg", [0.0, 135.0])
def test_low_grasp_parts_are_planned_clear_of_belt_and_part(name, yaw_deg):
    b = CATALOGUE[name].geometry().bounds
    a = math.radians(yaw_deg)
    T = np.eye(4)
    T[:2, :2] = [[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]]
    T[:3, 3] = LAYOUT.conveyor.station_point
    bin_ = next(x for x in LAYOUT.bins if CATALOGUE[name].base_of in x.parts)
    g = suction_point(name)
    assert g[2] < 0.02  # the sealing patch is low: a flange ring, a bracket's plate
    plan = plan_pick_place(ASEA.q_ready, T, float(b[1, 2]), bin_.drop_point,
                           object_radius_m=float(np.abs(b[:, :2]).max()), grasp_obj=g,
                           world=WORLD)  # fmt: skip
    lip = plan.T_base_lip_grasp[:3, 3]
    want = T[:3, :3] @ g + T[:3, 3]
    assert np.linalg.norm(lip[:2] - want[:2]) < 1e-3 and abs(lip[2] - (want[2] - 0.004)) < 1e-3
    # No part of the tool (other than the lip) comes near the part on the way down.
    assert _gap_to_part(name, T, [plan.steps[0].trajectory, plan.steps[1].trajectory]) > 0.0
