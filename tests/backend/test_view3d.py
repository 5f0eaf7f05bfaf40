"""The viser 3D view: pinned port, arm geometry from the model, panel wired to the cell."""

from __future__ import annotations

import asyncio
import socket

import numpy as np
import pytest

from backend.cell import Cell
from backend.view3d import View3D
from backend.view3d.arm import arm_shapes, link_poses
from robot.drivers import IdealDriver
from robot.kinematics import T_base_ee, joint_positions
from robot.model import ASEA
from tests.utils.factories import free_port, make_settings
from vision.sources import ImageFolderCamera


def test_link_poses_follow_the_kinematic_chain():
    rng = np.random.default_rng(0)
    for q in rng.uniform(ASEA.lower, ASEA.upper, size=(20, 5)):
        poses = link_poses(q, ASEA)
        pts = joint_positions(q, ASEA)
        for i, (shape, T) in enumerate(zip(arm_shapes(ASEA), poses[:-1], strict=True)):
            np.testing.assert_allclose(T[:3, 3], pts[i], atol=1e-12)
            end = T[:3, 3] + T[:3, 0] * shape.length_m  # parts extend along local +x
            np.testing.assert_allclose(end, pts[i + 1], atol=1e-12)
        np.testing.assert_allclose(poses[-1], T_base_ee(q, ASEA), atol=1e-12)


@pytest.fixture
async def cell(tmp_path):
    # Real-time moves (about 1 s) so the 30 Hz view has many updates to count.

    settings = make_settings(tmp_path)
    c = Cell(
        settings, IdealDriver(time_scale=1.0), ImageFolderCamera(settings.resolved_camera_folder())
    )
    await c.start()
    yield c
    await c.stop()


async def test_view_starts_on_its_pinned_port_and_tracks_the_arm(cell):
    port = free_port()
    view = View3D(cell, host="127.0.0.1", port=port)
    await view.start()
    try:
        assert view.port == port
        await asyncio.sleep(0.1)
        before = view.updates
        job = cell.move_joints(ASEA.q_ready, speed=1.0)
        await cell.jobs.wait(job)
        await asyncio.sleep(0.1)
        assert job.state.value == "done", job.public()
        assert view.updates > before + 2, (view.updates, before, job.result)
        ee = view._handles[-1]
        # Drawn where the arm is: the move ends within its tolerance of the target (a few
        # micrometres were seen on a loaded machine), so 0.1 mm, not 1e-6 m.
        np.testing.assert_allclose(ee.position, T_base_ee(ASEA.q_ready)[:3, 3], atol=1e-4)
        # The panel's buttons are per client and follow roles: tests/backend/test_view3d_panel.py.
    finally:
        await view.stop()


async def test_taken_port_fails_with_a_clear_message(cell):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        view = View3D(cell, host="127.0.0.1", port=port)
        with pytest.raises(RuntimeError, match=f"viser port {port} on 127.0.0.1 is taken"):
            await view.start()
