"""Offscreen MuJoCo rendering on one dedicated thread.

OpenGL contexts belong to the thread that made them current, and MuJoCo's renderer keeps
GPU-side copies of the model; so one :class:`RenderWorker` thread creates the context, owns a
private copy of the model and data, and runs every render job.  Jobs are plain callables
handed over through a queue; results come back as ``concurrent.futures.Future``.  With
``MUJOCO_GL=egl`` and no GPU, Mesa renders on the CPU.
"""

from __future__ import annotations

import atexit
import concurrent.futures
import copy
import logging
import queue
import threading
import weakref
from collections.abc import Callable
from typing import Any, TypeVar

import mujoco
import numpy as np
from numpy.typing import NDArray

__all__ = ["OffscreenRenderer", "RenderWorker"]

log = logging.getLogger(__name__)
T = TypeVar("T")

# Render threads still running at interpreter exit are closed before MuJoCo's EGL module
# terminates the display (its own exit hook); atexit runs hooks in reverse order of
# registration, so ours is registered after the first context exists.
_LIVE: weakref.WeakSet[RenderWorker] = weakref.WeakSet()
_exit_hook_registered = False


def _close_all() -> None:
    for worker in list(_LIVE):
        worker.close(timeout=2.0)


class OffscreenRenderer:
    """Renders one fixed camera of a model into RGB and metric depth.

    Must be created, used and closed on the same thread.
    """

    def __init__(self, model: mujoco.MjModel, width: int, height: int, camera: str) -> None:
        if width > model.vis.global_.offwidth or height > model.vis.global_.offheight:
            raise ValueError(
                f"render size {width}x{height} exceeds the offscreen buffer "
                f"{model.vis.global_.offwidth}x{model.vis.global_.offheight}"
            )
        cam_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, camera)
        if cam_id < 0:
            raise ValueError(f"model has no camera named {camera!r}")
        self.model = model
        self.width, self.height = width, height
        self._gl = mujoco.GLContext(width, height)
        self._gl.make_current()
        self._con = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_100)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, self._con)
        self._con.readDepthMap = mujoco.mjtDepthMap.mjDEPTH_ZEROFAR
        self._scene = mujoco.MjvScene(model, maxgeom=max(1000, 2 * model.ngeom))
        self._opt = mujoco.MjvOption()
        self._cam = mujoco.MjvCamera()
        self._cam.type = mujoco.mjtCamera.mjCAMERA_FIXED
        self._cam.fixedcamid = cam_id
        self._rect = mujoco.MjrRect(0, 0, width, height)
        self._rgb = np.empty((height, width, 3), np.uint8)
        self._depth = np.empty((height, width), np.float32)
        extent = model.stat.extent
        near = np.float64(np.float32(model.vis.map.znear * extent))
        far = np.float64(np.float32(model.vis.map.zfar * extent))
        # OpenGL's perspective depth, remapped by MuJoCo's reversed-Z convention: window
        # depth d relates to eye distance z by z = D / (d + C) (see glFrustum).
        c = -(far + near) / (far - near)
        dd = -2.0 * far * near / (far - near)
        self._C, self._D = -0.5 * c - 0.5, -0.5 * dd

    def render(
        self, data: mujoco.MjData, *, depth: bool = False
    ) -> tuple[NDArray[np.uint8], NDArray[np.float32] | None]:
        """RGB (row 0 at the top) and, if asked, the distance along the optical axis in metres."""
        if self._con is None:
            raise RuntimeError("renderer is closed")
        mujoco.mjv_updateScene(
            self.model, data, self._opt, None, self._cam, mujoco.mjtCatBit.mjCAT_ALL, self._scene
        )
        mujoco.mjr_render(self._rect, self._scene, self._con)
        mujoco.mjr_readPixels(self._rgb, self._depth if depth else None, self._rect, self._con)
        rgb = np.flipud(self._rgb).copy()
        if not depth:
            return rgb, None
        z = (self._D / (np.flipud(self._depth).astype(np.float64) + self._C)).astype(np.float32)
        return rgb, z

    def render_geom_ids(self, data: mujoco.MjData) -> NDArray[np.int32]:
        """The id of the model geom seen at each pixel (row 0 at the top), ``-1`` where none.

        MuJoCo's segmentation rendering (``mjRND_SEGMENT`` with ``mjRND_IDCOLOR``): lighting,
        textures and fog are off and every scene geom is drawn in a flat colour encoding its
        index in the scene plus one (``r + 256 g + 65536 b``; 0 is the background).  The index
        is mapped back to the model geom (``mjvGeom.objid`` of geoms of type ``mjOBJ_GEOM``);
        decorative scene geoms (none in the cell's camera view) give ``-1``.  Geoms with alpha 0
        (hidden objects) are not drawn.  With multisampling (``offsamples > 0``) the colours of
        edge pixels are averaged and can decode to a wrong id, so the cell renders without it
        (the default of :class:`~robot.sim.config.SimConfig`).
        """
        if self._con is None:
            raise RuntimeError("renderer is closed")
        scn = self._scene
        mujoco.mjv_updateScene(
            self.model, data, self._opt, None, self._cam, mujoco.mjtCatBit.mjCAT_ALL, scn
        )
        scn.flags[mujoco.mjtRndFlag.mjRND_SEGMENT] = 1
        scn.flags[mujoco.mjtRndFlag.mjRND_IDCOLOR] = 1
        try:
            mujoco.mjr_render(self._rect, scn, self._con)
        finally:
            scn.flags[mujoco.mjtRndFlag.mjRND_SEGMENT] = 0
            scn.flags[mujoco.mjtRndFlag.mjRND_IDCOLOR] = 0
        seg = np.empty((self.height, self.width, 3), np.uint8)
        mujoco.mjr_readPixels(seg, None, self._rect, self._con)
        code = seg.astype(np.int32)
        code = code[..., 0] | (code[..., 1] << 8) | (code[..., 2] << 16)
        n = scn.ngeom
        lut = np.full(n + 2, -1, np.int32)  # code 0 = background; codes past n: not a geom
        for i in range(n):
            g = scn.geoms[i]
            if g.objtype == mujoco.mjtObj.mjOBJ_GEOM and 0 <= g.segid < n:
                lut[g.segid + 1] = g.objid
        np.minimum(code, n + 1, out=code)
        return np.flipud(lut[code]).copy()

    def close(self) -> None:
        """Free the GL resources (on the creating thread)."""
        if self._con is not None:
            self._con.free()
            self._con = None
        if self._gl is not None:
            self._gl.free()
            self._gl = None


class RenderWorker:
    """A thread that owns the GL context and a private copy of the model.

    Parameters
    ----------
    model : mujoco.MjModel
        Copied at start; the worker's jobs see only the copy (``worker.model``).
    width, height : int
        Render size.
    camera : str
        Name of the model camera to render.
    """

    def __init__(self, model: mujoco.MjModel, width: int, height: int, camera: str) -> None:
        self.model = copy.deepcopy(model)
        self.data = mujoco.MjData(self.model)
        self._size = (width, height)
        self._camera = camera
        self._jobs: queue.Queue[
            tuple[Callable[..., Any], concurrent.futures.Future[Any]] | None
        ] = queue.Queue()
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self.renderer: OffscreenRenderer | None = None
        self._thread = threading.Thread(target=self._run, name="sim-render", daemon=True)
        self._thread.start()
        self._ready.wait(timeout=60.0)
        if self._error is not None:
            raise RuntimeError(f"cannot start the MuJoCo renderer: {self._error}") from self._error
        global _exit_hook_registered
        if not _exit_hook_registered:
            atexit.register(_close_all)
            _exit_hook_registered = True
        _LIVE.add(self)

    def _run(self) -> None:
        try:
            self.renderer = OffscreenRenderer(self.model, *self._size, self._camera)
        except BaseException as exc:  # reported to the constructor's caller
            self._error = exc
            self._ready.set()
            return
        self._ready.set()
        try:
            while True:
                item = self._jobs.get()
                if item is None:
                    break
                fn, fut = item
                if not fut.set_running_or_notify_cancel():
                    continue
                try:
                    fut.set_result(fn(self))
                except BaseException as exc:
                    fut.set_exception(exc)
        finally:
            self.renderer.close()
            # Fail whatever is still queued.
            while True:
                try:
                    item = self._jobs.get_nowait()
                except queue.Empty:
                    break
                if item is not None:
                    item[1].set_exception(RuntimeError("renderer closed"))

    def submit(self, fn: Callable[[RenderWorker], T]) -> concurrent.futures.Future[T]:
        """Run ``fn(worker)`` on the render thread."""
        if not self._thread.is_alive():
            raise RuntimeError("renderer is closed")
        fut: concurrent.futures.Future[T] = concurrent.futures.Future()
        self._jobs.put((fn, fut))
        return fut

    def close(self, timeout: float = 5.0) -> None:
        """Finish the running job, release the GL context and end the thread."""
        if self._thread.is_alive():
            self._jobs.put(None)
            self._thread.join(timeout)
