"""The 3D view of the simulated cell: objects and boards from the simulation, live frames."""

from __future__ import annotations

import asyncio

import msgspec
import numpy as np
import pytest
import viser
import websockets

from backend.cell import Cell
from backend.hardware import make_hardware
from backend.view3d import View3D
from tests.utils.factories import free_port, make_settings


async def _fake_browser(port: int) -> websockets.ClientConnection:
    """A viser client: the websocket plus the first camera message, after which viser
    counts the client as connected (what a browser tab does)."""
    from viser._messages import ViewerCameraMessage

    ws = await websockets.connect(
        f"ws://127.0.0.1:{port}", subprotocols=[f"viser-v{viser.__version__}"]
    )
    msg = ViewerCameraMessage(
        wxyz=(1.0, 0.0, 0.0, 0.0),
        position=(2.0, -2.0, 1.5),
        fov=1.0,
        near=0.01,
        far=100.0,
        image_height=480,
        image_width=640,
        look_at=(0.4, 0.0, 0.6),
        up_direction=(0.0, 0.0, 1.0),
    )
    await ws.send(msgspec.msgpack.encode(msg.as_serializable_dict()))
    return ws


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
    port = free_port()
    view = View3D(cell, host="127.0.0.1", port=port, sim=sim, image_rate_hz=20.0, sim_rate_hz=20.0)
    await view.start()
    browser = None
    try:
        await asyncio.sleep(0.5)
        assert view.image_updates == 0  # nobody looks: the frustum reads no frames
        # A browser connects (viser's websocket): live frames flow to the frustum.
        browser = await _fake_browser(port)
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
        # The belt moves on while the scene catches up: each object's drawn position lies
        # between the simulation's positions read before and after an update that started
        # after the first read (two updates later), however late the update thread runs.
        before = {o.id: o.T_base_obj[:3, 3].copy() for o in sim.objects()}
        seen = scene.updates
        for _ in range(300):
            await asyncio.sleep(0.02)
            if scene.updates >= seen + 2:
                break
        drawn = {i: np.array(entry[0].position) for i, entry in scene._objects.items()}
        objects = sim.objects()
        after = {o.id: o.T_base_obj[:3, 3] for o in objects}
        # (an object the demo adds or removes in between may or may not be drawn yet)
        assert set(before) & set(after) <= set(drawn) <= set(before) | set(after)
        assert len(objects) >= 5
        for i in set(before) & set(after) & set(drawn):
            if after[i][1] < before[i][1] - 0.01:
                continue  # recycled in between: carried off the end, put back at the start
            lo = np.minimum(before[i], after[i]) - 0.002
            hi = np.maximum(before[i], after[i]) + 0.002
            assert np.all((drawn[i] >= lo) & (drawn[i] <= hi)), (i, drawn[i], before[i], after[i])
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
        if browser is not None:
            await browser.close()
        await view.stop()
