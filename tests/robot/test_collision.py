"""The planning collision check: arm capsules against boxes and the floor."""

from __future__ import annotations

import math

import numpy as np
import pytest

from robot.collision import Box, CollisionWorld, box_distance
from robot.kinematics import joint_positions
from robot.model import ASEA


def test_box_distance():
    b = Box("b", (0.0, 0.0, 0.0), (1.0, 1.0, 1.0))
    d = box_distance([[0.5, 0.5, 0.5], [2.0, 0.5, 0.5], [2.0, 2.0, 0.5]], b)
    np.testing.assert_allclose(d, [0.0, 1.0, math.sqrt(2.0)])


def test_ready_pose_is_free_and_a_box_on_the_forearm_is_hit():
    world = CollisionWorld()
    assert world.contacts(ASEA.q_ready) == []
    p = joint_positions(ASEA.q_ready)
    mid = 0.5 * (p[2] + p[3])  # middle of the forearm
    hit = world.with_boxes(Box.around("crate", [mid], pad_m=0.01))
    contacts = hit.contacts(ASEA.q_ready)
    assert {c.link for c in contacts} >= {"forearm"}
    assert all(c.obstacle == "crate" for c in contacts)
    assert "mm from the crate" in str(contacts[0])


def test_a_raised_floor_is_hit_by_the_tools_first():
    # The joint ranges keep the flange well above the real floor; raise the plane instead.
    # At q_ready the flange is at z = 1.0 m pointing down, the shoulder at 0.73 m.
    world = CollisionWorld(floor_z_m=0.91)
    contacts = {c.link: c for c in world.contacts(ASEA.q_ready)}
    assert set(contacts) == {"upper_arm", "camera", "cup"}
    assert contacts["cup"].obstacle == "floor"
    # The cup's capsule ends 95 mm past the flange face (radius 13 mm), the camera's 30 mm
    # (radius 42 mm).
    assert contacts["cup"].clearance_m == pytest.approx(1.0 - 0.095 - 0.013 - 0.91, abs=1e-6)
    assert contacts["camera"].clearance_m == pytest.approx(1.0 - 0.03 - 0.042 - 0.91, abs=1e-6)
    assert CollisionWorld(floor_z_m=0.5).contacts(ASEA.q_ready) == []
    assert world.path_contacts(ASEA.q_home, ASEA.q_ready)
    assert CollisionWorld().path_contacts(ASEA.q_home, ASEA.q_ready) == []


def test_bad_input():
    with pytest.raises(ValueError, match="lower must be <= upper"):
        Box("x", (1.0, 0.0, 0.0), (0.0, 1.0, 1.0))
    with pytest.raises(ValueError, match="q must be 5 finite joint values"):
        CollisionWorld().contacts([0.0, 1.0])


def test_sim_cell_furniture():
    from robot.sim.bins import default_bins
    from robot.sim.obstacles import collision_world

    world = collision_world()
    names = {b.name for b in world.boxes}
    assert {"table", "conveyor", "conveyor rail inner", "conveyor rail outer"} <= names
    assert {n for n in names if n.startswith("bin ")} == {f"bin {b.name}" for b in default_bins()}
    assert not world.collides(ASEA.q_ready)
