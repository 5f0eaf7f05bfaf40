"""The viser 3D view: the arm drawn from the model, the camera frustum with the live image,
the simulated conveyor and objects, a control panel per client.

viser runs its own web server (own port, own thread) with no authentication hook.  The
shared panel holds read-outs only (driver status, joints); every control lives in a
per-client panel (:mod:`backend.view3d.panel`) that follows the client's grant
(:mod:`backend.view3d.access`): anonymous clients see the scene only.  A client signs in
with an API token typed into its panel, or arrives signed in through a short-lived link
that the console puts into its embedded view's websocket URL
(``?websocket=ws://HOST:PORT/vc-link/LINK``).  GUI callbacks run on viser's threads; they
hand work to the application's event loop with ``asyncio.run_coroutine_threadsafe``,
through the same :class:`~backend.cell.Cell` methods the REST endpoints use.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np
import viser
import viser.transforms as vtf

from backend.calibration.autoplan import NOMINAL_T_EE_CAM
from backend.cell import Cell
from backend.view3d.access import ViewAccess, link_from_path
from backend.view3d.arm import arm_shapes, link_poses
from backend.view3d.calibviews import CalibrationFrusta
from backend.view3d.clients import _client_address, _request_path
from backend.view3d.guard import MessageGuard
from backend.view3d.panel import ClientPanel
from backend.view3d.simscene import SimScene

if TYPE_CHECKING:
    from robot.sim import SimEngine

__all__ = ["T_EE_CAM_PLACEHOLDER", "View3D"]

log = logging.getLogger(__name__)

#: Where the frustum is drawn until a hand-eye calibration is active: the drawing's
#: mounting, the same one the calibration planner starts from.
T_EE_CAM_PLACEHOLDER = NOMINAL_T_EE_CAM
#: Where a new view's camera stands and what it looks at, base frame, metres.
INITIAL_CAMERA_M = (2.2, -1.9, 1.7)
INITIAL_LOOK_AT_M = (0.45, 0.0, 0.75)
#: Height of the console's embedded 3D view (web/style.css, 32rem), CSS pixels.
EMBEDDED_VIEW_PX = 512.0


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
    access : ViewAccess, optional
        Who may do what (:mod:`backend.view3d.access`).  Without it every client sees the
        scene only: no control is ever shown.
    recheck_s : float
        How often signed-in clients' tokens are looked up again (revocation, role changes).
    bins : tuple of robot.cellworld.Bin, optional
        The sorting bins drawn (the cell's layout; default: the simulator's, else none).
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
        access: ViewAccess | None = None,
        recheck_s: float = 2.0,
        bins: tuple[Any, ...] | None = None,
    ) -> None:
        if not 0.05 <= recheck_s <= 60.0:
            raise ValueError(f"recheck_s must be in [0.05, 60] s, got {recheck_s!r}")
        self.cell = cell
        self.access = access
        self.recheck_s = float(recheck_s)
        #: The panel of each connected client, by viser client id.
        self.panels: dict[int, ClientPanel] = {}
        self.host = host
        self.requested_port = port
        self.rate_hz = rate_hz
        self.image_rate_hz = image_rate_hz
        self.sim_rate_hz = sim_rate_hz
        self.sim = sim
        self._bins = bins
        self.server: viser.ViserServer | None = None
        self._task: asyncio.Task[None] | None = None
        self._recheck_task: asyncio.Task[None] | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._handles: list[Any] = []
        self._frustum: Any = None
        self._sim_scene: SimScene | None = None
        self._calib_frusta: CalibrationFrusta | None = None
        self.updates = 0
        self.image_updates = 0
        #: Drops (and logs once per client) what clients send that viser cannot handle.
        self._guard = MessageGuard()
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
        self._guard.install(server)
        # The panel docked at the right edge, narrow: it takes its strip of the view instead
        # of floating over the cell (in the console's embedded view at 1280 px a floating
        # panel hid half of the scene); docked panels can still be collapsed by the user.
        server.gui.configure_theme(control_width="small", show_share_button=False)
        server.gui.main_panel.dock_right()
        server.scene.set_up_direction("+z")
        server.initial_camera.position = INITIAL_CAMERA_M
        server.initial_camera.look_at = INITIAL_LOOK_AT_M
        self._build_scene(server)
        self._build_panel(server)
        self._task = asyncio.create_task(self._update_loop(), name="view3d-update")
        self._recheck_task = asyncio.create_task(self._recheck_loop(), name="view3d-access")

    async def stop(self) -> None:
        """Stop the update task and the server."""
        for task in (self._task, self._recheck_task):
            if task is not None:
                task.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await task
        if self._calib_frusta is not None:
            self._calib_frusta.close()
        if getattr(self, "_inspection_scene", None) is not None:
            self._inspection_scene.close()
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
        # The latest inspection and the sorting bins (backend.inspection).
        from backend.view3d.inspections import InspectionScene, LabelCamera

        bins = self._bins
        if bins is None:
            bins = () if self.sim is None else self.sim.config.layout.bins
        first_view = LabelCamera(INITIAL_CAMERA_M, INITIAL_LOOK_AT_M,
                                 fov_rad=server.initial_camera.fov, height_px=EMBEDDED_VIEW_PX)  # fmt: skip
        self._inspection_scene = InspectionScene(
            server, self.cell.bus, bins, fov_rad=self._fov_rad, aspect=self._aspect,
            labels_for=first_view,
        )  # fmt: skip

    def _build_panel(self, server: viser.ViserServer) -> None:
        gui = server.gui
        self._status_md = gui.add_markdown("**Driver:** starting")
        # Read-outs as text: the shared panel has no input any client could send values to.
        with gui.add_folder("Joints (deg)"):
            self._joints_md = gui.add_markdown("")
        server.on_client_connect(self._on_connect)
        server.on_client_disconnect(self._on_disconnect)

    # -- per-client panels ---------------------------------------------------------------
    def _on_connect(self, client: viser.ClientHandle) -> None:
        """A browser connected (viser's thread): anonymous until a grant arrives."""
        assert self._loop is not None
        self._guard.attach(client)
        panel = ClientPanel(
            client, cell=self.cell, access=self.access, loop=self._loop, sim=self.sim
        )
        open_grant = self.access.open_grant() if self.access is not None else None
        panel.apply(open_grant)
        # Unknown address (viser internals changed): throttle the view's clients as one.
        panel.address = _client_address(self.server, client.client_id) or "view3d"
        self.panels[client.client_id] = panel
        link = link_from_path(_request_path(self.server, client.client_id))
        access = self.access
        if access is not None and link is not None and open_grant is None:

            async def from_link() -> None:
                grant = await access.from_link(link)
                if grant is None:
                    panel.say("The console link has expired or is not valid: sign in with a token.")
                else:
                    panel.apply(grant)

            panel.submit(from_link(), clear=False)

    def _on_disconnect(self, client: viser.ClientHandle) -> None:
        self._guard.forget(client.client_id)
        panel = self.panels.pop(client.client_id, None)
        if panel is not None:
            panel.close()

    async def _recheck_loop(self) -> None:
        """Follow token revocation, disabled users and role changes of signed-in clients."""
        while True:
            await asyncio.sleep(self.recheck_s)
            if self.access is None:
                continue
            for panel in list(self.panels.values()):
                grant = panel.grant
                if grant is None or grant.token_id is None:
                    continue
                try:
                    fresh = await self.access.recheck(grant)
                except Exception:  # a database hiccup must not end the loop
                    log.exception("3D view: re-checking a client's grant failed")
                    continue
                if fresh != grant and panel.grant == grant:
                    panel.apply(fresh)
                    if fresh is None:
                        panel.say("Signed out: the token was revoked or the user disabled.")

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
        text = "  \n".join(
            f"q{i + 1}: {math.degrees(value):8.2f}" for i, value in enumerate(state.q)
        )
        if self._joints_md.content != text:
            self._joints_md.content = text
