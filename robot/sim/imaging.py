"""From a snapshot of the cell to the image the camera records.

Steps, all on the render thread: load the snapshot into the render model, render the ideal
pinhole canvas (with depth when the arm moves), blur it with the camera's motion during the
exposure, apply the lens (chapter eqs. 3-5 via :meth:`vision.camera.PinholeCamera.distort_maps`),
then exposure, gain and noise.

:func:`object_masks` gives the ground-truth silhouettes of the objects in such an image:
MuJoCo's segmentation render of the same snapshot (the geom id at each pixel,
:meth:`~robot.sim.render.OffscreenRenderer.render_geom_ids`) through the same lens, the nearest
ideal pixel per image pixel (no blur, no noise: the masks are of the still scene).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robot.model import ASEA, ArmModel
from robot.sim.camera import CameraSpec, Lens, Sensor, exposure_end_poses, motion_blur
from robot.sim.engine import SimEngine, Snapshot
from robot.sim.render import RenderWorker

__all__ = ["CameraImage", "Imager", "capture", "geom_id_image", "object_masks"]

_STILL_RAD_S = 1e-3  # below this joint speed the exposure is treated as still


@dataclass(frozen=True)
class CameraImage:
    """One exposure: the recorded image and the snapshot it shows."""

    rgb: NDArray[np.uint8]
    snapshot: Snapshot
    blurred: bool


class Imager:
    """Turns snapshots into camera images for one :class:`CameraSpec`.

    Parameters
    ----------
    spec : CameraSpec
        Must match the geometry the engine was built with (size, field of view, mounting);
        the sensor fields (noise, exposure, gain, blur) may differ.
    model : ArmModel
        For the camera's motion during the exposure.
    """

    def __init__(self, spec: CameraSpec, *, model: ArmModel = ASEA) -> None:
        self.spec = spec
        self.lens = Lens(spec)
        self.arm_model = model
        self.sensor = Sensor(spec)
        _ = self.lens.maps  # build the remap tables now, not on the first frame

    def set_sensor(self, spec: CameraSpec) -> None:
        """Change the sensor settings (the lens and mounting must stay the same)."""
        geometry = ("width", "height", "fovy_deg", "dist")
        for name in geometry:
            if getattr(spec, name) != getattr(self.spec, name):
                raise ValueError(f"cannot change the camera's {name} at run time")
        if not np.array_equal(spec.T_ee_cam, self.spec.T_ee_cam):
            raise ValueError("cannot change the camera's mounting at run time")
        self.spec = spec

    def render(self, worker: RenderWorker, snap: Snapshot) -> CameraImage:
        """Run on the render thread: the image of ``snap``."""
        spec = self.spec
        SimEngine.apply_snapshot(worker.model, worker.data, snap)
        assert worker.renderer is not None
        moving = spec.motion_blur and float(np.abs(snap.qd).max()) > _STILL_RAD_S
        ideal, depth = worker.renderer.render(worker.data, depth=moving)
        blurred = False
        if moving and depth is not None:
            T0, T1 = exposure_end_poses(spec, snap.q, snap.qd, model=self.arm_model)
            out = motion_blur(ideal, depth, self.lens.K_ideal, T0, T1)
            blurred = out is not ideal
            ideal = out
        rgb = self.sensor.apply(self.lens.distort(ideal), spec)
        return CameraImage(rgb, snap, blurred)

    def geom_ids(self, worker: RenderWorker, snap: Snapshot) -> NDArray[np.int32]:
        """Run on the render thread: the model geom id at each pixel of ``snap``'s image
        (``-1`` for the background), through the lens."""
        SimEngine.apply_snapshot(worker.model, worker.data, snap)
        assert worker.renderer is not None
        return self.lens.distort_labels(worker.renderer.render_geom_ids(worker.data))


def capture(
    engine: SimEngine, q: ArrayLike | None = None, *, spec: CameraSpec | None = None
) -> CameraImage:
    """Put the arm at ``q`` (if given, at rest) and take one picture, synchronously.

    For tests, benchmarks and calibration studies that do not run an event loop; the
    product grabs frames through :class:`~robot.sim.driver.SimCamera`.  ``spec`` overrides
    the sensor settings (noise, exposure, gain, blur) of the engine's camera.
    """
    if q is not None:
        engine.set_joints(q)
    imager = Imager(spec or engine.config.camera, model=engine.arm_model)
    snap = engine.snapshot()
    return engine.renderer().submit(lambda w: imager.render(w, snap)).result()


def geom_id_image(engine: SimEngine, snapshot: Snapshot | None = None) -> NDArray[np.int32]:
    """The model geom id seen at each pixel of the camera image of ``snapshot`` (default:
    now), ``-1`` where no geom is; same size and lens as :func:`capture`'s image."""
    imager = Imager(engine.config.camera, model=engine.arm_model)
    snap = snapshot if snapshot is not None else engine.snapshot()
    return engine.renderer().submit(lambda w: imager.geom_ids(w, snap)).result()


def object_masks(
    engine: SimEngine, snapshot: Snapshot | None = None, *, ids: Iterable[int] | None = None
) -> dict[int, NDArray[np.bool_]]:
    """Ground-truth silhouette of each object on the belt in the camera image.

    Parameters
    ----------
    engine : SimEngine
    snapshot : Snapshot, optional
        The instant to mask, e.g. ``capture(...).snapshot`` for the image just taken
        (default: now).  The objects must still be on the belt.
    ids : iterable of int, optional
        Object ids (default: every object on the belt).

    Returns
    -------
    dict of int to ndarray of shape (H, W), bool
        Per object id, the pixels where one of the object's geoms is the nearest surface
        (occlusion included: a part hidden by another object or by the arm is not in its mask).
    """
    wanted = [o.id for o in engine.objects()] if ids is None else [int(i) for i in ids]
    geoms = {obj_id: engine.object_geoms(obj_id) for obj_id in wanted}
    labels = geom_id_image(engine, snapshot)
    return {obj_id: np.isin(labels, g) for obj_id, g in geoms.items()}
