"""The 3D view of the simulated cell: objects and boards from the simulation, live frames."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest

from backend.cell import Cell
from backend.hardware import make_hardware
from backend.view3d import View3D
from tests.utils.factories import free_port, make_settings


@pytest.fixture
async def sim_cell(tmp_path):
    settings = make_settings(tmp_path, driver="sim", camera="sim", sim_demo=True, camera_fps=10.0)
    hw = await asyncio.to_thread(make_hardware, settings)
    cell = Cell(settings, hw.driver, hw.camera)
    await cell.start()
    yield cell, hw.sim
    await cell.stop()
    hw.sim.stop()


async def test_view_draws_the_simulated_cell_and_live_frames(sim_cell):
    cell, sim = sim_cell
    view = View3D(
        cell, host="127.0.0.1", port=free_port(), sim=sim, image_rate_hz=20.0, sim_rate_hz=20.0
    )
    await view.start()
    try:
        # The frustum sits at the simulated camera's true mounting, with its field of view.
        np.testing.assert_allclose(view.T_ee_cam, sim.config.camera.T_ee_cam)
        np.testing.assert_allclose(view._frustum.position, sim.config.camera.T_ee_cam[:3, 3])
        assert view._frustum.fov == pytest.approx(np.radians(sim.config.camera.fovy_deg))
        # A calibration can move it later.
        T = np.eye(4)
        T[:3, 3] = (0.0, 0.0, 0.1)
        view.T_ee_cam = T
        np.testing.assert_allclose(view._frustum.position, [0.0, 0.0, 0.1])
        with pytest.raises(ValueError, match="rigid transform"):
            view.T_ee_cam = np.zeros((4, 4))
        for _ in range(300):  # the first frame waits for the renderer to start
            await asyncio.sleep(0.05)
            if view.image_updates >= 2 and view._sim_scene.updates >= 2:
                break
        assert view.image_updates >= 2  # live frames reach the frustum
        scene = view._sim_scene
        objects = sim.objects()
        assert set(scene._objects) == {o.id for o in objects} and len(objects) >= 5
        for o in objects:
            handle = scene._objects[o.id][0]
            assert np.allclose(handle.position, o.T_base_obj[:3, 3], atol=0.05)  # the belt moves
        gone = objects[0].id
        sim.remove(gone)
        sim.place_board(
            "chessboard",
            np.diag([1.0, -1.0, -1.0, 1.0])
            + np.array([[0, 0, 0, 0], [0, 0, 0, -0.8], [0, 0, 0, 0.452], [0, 0, 0, 0]]),
        )
        await asyncio.sleep(0.3)
        assert gone not in scene._objects
        assert "chessboard" in scene._boards
    finally:
        await view.stop()
