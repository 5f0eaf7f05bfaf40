"""The viser 3D view: the arm drawn from the model, the camera frustum with the live image,
the simulated conveyor and objects, a control panel.

viser runs its own web server (own port, own thread).  Its GUI callbacks run on viser's
thread; they hand work to the application's event loop with
``asyncio.run_coroutine_threadsafe``, through the same :class:`~backend.cell.Cell` methods
the REST endpoints use.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from collections.abc import Coroutine
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np
import viser
import viser.transforms as vtf

from backend.calibration.autoplan import NOMINAL_T_EE_CAM
from backend.cell import Cell
from backend.view3d.arm import arm_shapes, link_poses
from backend.view3d.calibviews import CalibrationFrusta
from backend.view3d.simscene import SimScene
from vision.errors import VisionCellError

if TYPE_CHECKING:
    from robot.sim import SimEngine

__all__ = ["T_EE_CAM_PLACEHOLDER", "View3D"]

log = logging.getLogger(__name__)

#: Where the frustum is drawn until a hand-eye calibration is active: the drawing's
#: mounting, the same one the calibration planner starts from.
T_EE_CAM_PLACEHOLDER = NOMINAL_T_EE_CAM


def _wxyz(R: np.ndarray) -> np.ndarray:
    return vtf.SO3.from_matrix(R).wxyz


class View3D:
    """Owns the viser server of one cell.

    Parameters
    ----------
    cell : Cell
        Source of the arm state and target of the panel's buttons.
    host, port : str, int
        Where viser listens; the port is pinned (start fails if it is taken).
    rate_hz : float
        Scene update rate of the arm.
    sim : SimEngine, optional
        The simulated cell: its conveyor, objects and boards are drawn, and the frustum sits
        at the simulated camera's true mounting with its field of view.
    image_rate_hz : float
        How often the frustum's image is refreshed with the newest camera frame.
    sim_rate_hz : float
        How often the simulated objects' poses are refreshed.
    """

    def __init__(
        self,
        cell: Cell,
        *,
        host: str,
        port: int,
        rate_hz: float = 30.0,
        sim: SimEngine | None = None,
        image_rate_hz: float = 5.0,
        sim_rate_hz: float = 10.0,
    ) -> None:
        self.cell = cell
        self.host = host
        self.requested_port = port
        self.rate_hz = rate_hz
        self.image_rate_hz = image_rate_hz
        self.sim_rate_hz = sim_rate_hz
        self.sim = sim
        self.server: viser.ViserServer | None = None
        self._task: asyncio.Task[None] | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._handles: list[Any] = []
        self._frustum: Any = None
        self._sim_scene: SimScene | None = None
        self._calib_frusta: CalibrationFrusta | None = None
        self.updates = 0
        self.image_updates = 0
        self._fov_rad = math.radians(50.0)
        self._aspect = 4 / 3
        self._T_ee_cam = T_EE_CAM_PLACEHOLDER
        if sim is not None:
            # Until a hand-eye calibration is active, show the simulated camera where it is
            # truly mounted (the simulator's ground truth, shown to people, not used by
            # any algorithm).
            cam = sim.config.camera
            self._T_ee_cam = np.array(cam.T_ee_cam)
            self._fov_rad = math.radians(cam.fovy_deg)
            self._aspect = cam.width / cam.height

    @property
    def T_ee_cam(self) -> np.ndarray:
        """Where the frustum is drawn on the flange (4x4, OpenCV camera frame)."""
        return self._T_ee_cam

    @T_ee_cam.setter
    def T_ee_cam(self, T: np.ndarray) -> None:
        Ta = np.asarray(T, dtype=np.float64)
        if Ta.shape != (4, 4) or not np.allclose(Ta[:3, :3] @ Ta[:3, :3].T, np.eye(3), atol=1e-6):
            raise ValueError(f"T_ee_cam must be a 4x4 rigid transform, got {Ta.tolist()}")
        self._T_ee_cam = Ta
        if self._frustum is not None:
            self._frustum.wxyz = _wxyz(Ta[:3, :3])
            self._frustum.position = Ta[:3, 3]

    def set_camera_model(self, *, fov_rad: float, aspect: float) -> None:
        """Vertical field of view and aspect ratio of the drawn frustum."""
        if not (0.0 < fov_rad < math.pi) or not aspect > 0:
            raise ValueError(f"need 0 < fov_rad < pi and aspect > 0, got {fov_rad!r}, {aspect!r}")
        self._fov_rad, self._aspect = float(fov_rad), float(aspect)
        if self._frustum is not None:
            self._frustum.fov = self._fov_rad
            self._frustum.aspect = self._aspect

    @property
    def port(self) -> int:
        """The port viser listens on."""
        return self.server.get_port() if self.server is not None else self.requested_port

    def client_count(self) -> int:
        """Browsers connected to the 3D view."""
        return len(self.server.get_clients()) if self.server is not None else 0

    # -- life cycle ----------------------------------------------------------------------
    async def start(self) -> None:
        """Start viser, build the scene and the panel, start the update task."""
        self._loop = asyncio.get_running_loop()
        server = await asyncio.to_thread(
            viser.ViserServer, host=self.host, port=self.requested_port, verbose=False
        )
        if server.get_port() != self.requested_port:
            got = server.get_port()
            server.stop()
            raise RuntimeError(
                f"viser port {self.requested_port} on {self.host} is taken (viser moved to {got}); "
                "stop the other process or set VISIONCELL_VISER_PORT"
            )
        self.server = server
        server.scene.set_up_direction("+z")
        server.initial_camera.position = (2.2, -1.9, 1.7)
        server.initial_camera.look_at = (0.45, 0.0, 0.75)
        self._build_scene(server)
        self._build_panel(server)
        self._task = asyncio.create_task(self._update_loop(), name="view3d-update")

    async def stop(self) -> None:
        """Stop the update task and the server."""
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
        if self._calib_frusta is not None:
            self._calib_frusta.close()
        if self.server is not None:
            await asyncio.to_thread(self.server.stop)
            self.server = None

    # -- scene ---------------------------------------------------------------------------
    def _build_scene(self, server: viser.ViserServer) -> None:
        scene = server.scene
        scene.add_grid("/floor", width=4.0, height=4.0, cell_size=0.25, plane="xy")
        scene.add_frame("/world", axes_length=0.3, axes_radius=0.008)
        scene.add_light_hemisphere("/light", intensity=1.2)
        model = self.cell.model
        for shape in arm_shapes(model):
            frame = scene.add_frame(f"/arm/{shape.name}", show_axes=False)
            # Parts extend along the frame's +x; viser cylinders extend along their own +z.
            if shape.kind == "cylinder":
                scene.add_cylinder(
                    f"/arm/{shape.name}/geom",
                    radius=shape.width_m / 2,
                    height=shape.length_m,
                    color=shape.color,
                    wxyz=_wxyz(vtf.SO3.from_y_radians(math.pi / 2).as_matrix()),
                    position=(shape.length_m / 2, 0.0, 0.0),
                )
            else:
                scene.add_box(
                    f"/arm/{shape.name}/geom",
                    color=shape.color,
                    dimensions=(shape.length_m, shape.width_m, shape.width_m),
                    position=(shape.length_m / 2, 0.0, 0.0),
                )
            self._handles.append(frame)
        ee = scene.add_frame("/arm/ee", axes_length=0.08, axes_radius=0.005)
        self._handles.append(ee)
        self._frustum = scene.add_camera_frustum(
            "/arm/ee/camera",
            fov=self._fov_rad,
            aspect=self._aspect,
            scale=0.08,
            color=(40, 120, 220),
            format="jpeg",
            jpeg_quality=70,
            wxyz=_wxyz(self.T_ee_cam[:3, :3]),
            position=self.T_ee_cam[:3, 3],
        )
        self._image_index = -1
        if self.sim is not None:
            self._sim_scene = SimScene(server, self.sim)
        # Camera poses of automatic calibration runs (backend.calibration.auto).
        self._calib_frusta = CalibrationFrusta(
            server, self.cell.calibration_views, fov_rad=self._fov_rad, aspect=self._aspect
        )

    def _build_panel(self, server: viser.ViserServer) -> None:
        gui = server.gui
        self._status_md = gui.add_markdown("**Driver:** starting")
        with gui.add_folder("Joints (deg)"):
            self._joint_numbers = [
                gui.add_number(f"q{i + 1}", initial_value=0.0, disabled=True, step=0.01)
                for i in range(5)
            ]
        self._speed = gui.add_slider(
            "Speed", min=0.05, max=1.0, step=0.05, initial_value=self.cell.speed
        )
        home = gui.add_button("Home")
        stop = gui.add_button("Stop")
        estop = gui.add_button("E-STOP", color="red")
        reset = gui.add_button("Reset E-STOP")
        self._message_md = gui.add_markdown("")

        @self._speed.on_update
        def _(_: Any) -> None:
            self.cell.speed = float(self._speed.value)

        @home.on_click
        def _(_: Any) -> None:
            self._submit(self._home())

        @stop.on_click
        def _(_: Any) -> None:
            self._submit(self.cell.stop_motion())

        @estop.on_click
        def _(_: Any) -> None:
            self._submit(self.cell.estop())

        @reset.on_click
        def _(_: Any) -> None:
            self._submit(self.cell.reset())

    async def _home(self) -> None:
        self.cell.home()

    def _submit(self, coro: Coroutine[Any, Any, Any]) -> None:
        """Run ``coro`` on the application loop (called from viser's thread)."""
        assert self._loop is not None
        fut = asyncio.run_coroutine_threadsafe(coro, self._loop)

        def done(f: Any) -> None:
            exc = f.exception()
            if exc is not None and self.server is not None:
                text = exc.detail if isinstance(exc, VisionCellError) else str(exc)
                self._message_md.content = f"**Refused:** {text}"
            elif self.server is not None:
                self._message_md.content = ""

        fut.add_done_callback(done)

    # -- updates -------------------------------------------------------------------------
    async def _update_loop(self) -> None:
        period = 1.0 / self.rate_hz
        last_panel = last_image = last_sim = 0.0
        last_q: tuple[float, ...] | None = None
        while True:
            t0 = time.monotonic()
            state = self.cell.driver.state
            server = self.server
            if server is not None:
                if state.q != last_q:
                    poses = link_poses(state.q, self.cell.model)
                    with server.atomic():
                        for handle, T in zip(self._handles, poses, strict=True):
                            handle.wxyz = _wxyz(T[:3, :3])
                            handle.position = T[:3, 3]
                    last_q = state.q
                    self.updates += 1
                if t0 - last_panel > 0.2:
                    last_panel = t0
                    self._update_panel(state)
                if t0 - last_image >= 1.0 / self.image_rate_hz:
                    last_image = t0
                    self._update_image()
                if self._sim_scene is not None and t0 - last_sim >= 1.0 / self.sim_rate_hz:
                    last_sim = t0
                    self._sim_scene.update()
            await asyncio.sleep(max(0.0, period - (time.monotonic() - t0)))

    def _update_image(self) -> None:
        """Show the newest camera frame in the frustum (only the latest; never a backlog).

        Nothing is read while no browser is connected, so the camera may idle.
        """
        if self.client_count() == 0:
            return
        frame = self.cell.latest_frame
        if frame is None or frame.index == self._image_index or self._frustum is None:
            return
        self._image_index = frame.index
        small = cv2.resize(frame.rgb, (320, 240), interpolation=cv2.INTER_AREA)
        self._frustum.image = small
        h, w = frame.rgb.shape[:2]
        self._frustum.aspect = w / h
        self.image_updates += 1

    def _update_panel(self, state: Any) -> None:
        flags = []
        flags.append("connected" if state.connected else "**DISCONNECTED**")
        if state.moving:
            flags.append("moving")
        if state.estopped:
            flags.append("**E-STOP**")
        if state.fault:
            flags.append(f"fault: {state.fault}")
        self._status_md.content = f"**Driver:** {self.cell.driver.name} ({', '.join(flags)})"
        for number, value in zip(self._joint_numbers, state.q, strict=True):
            deg = round(math.degrees(value), 2)
            if number.value != deg:
                number.value = deg
