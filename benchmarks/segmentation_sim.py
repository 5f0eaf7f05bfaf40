"""Segmentation benchmark images rendered by the simulated cell: wheels on the belt.

Procedure (``sim`` provider of :mod:`benchmarks.segmentation_cases`), rendered afresh on every
run (nothing is stored):

1. One :class:`~robot.sim.SimEngine` with the default cell and camera (640x480, the default
   barrel-distortion lens, read and shot noise seeded with the engine's seed 0, no motion
   blur since the arm is still).
2. For each wheel type of :data:`WHEELS` in turn, the wheel alone at the belt's station on
   its centre line, turned by the yaw listed there, the belt stopped; the arm at the
   ``top`` viewpoint 0.55 m above the wheel's top face (:func:`robot.sim.poses.viewpoint`, the
   approach axis straight down): an eye-in-hand top view of the wheel on the belt, with the
   belt's cleats beside it and the edge of the table in the frame.
3. The image is the camera's (:func:`robot.sim.imaging.capture`).  The reference mask is
   MuJoCo's segmentation render of the same snapshot (:func:`robot.sim.imaging.object_masks`:
   the geom id at each pixel through the same lens; the pixels showing one of the wheel's
   geoms), so it is exact up to the lens resampling (nearest pixel, half a pixel at most).
4. The initial contour, like the hand-placed ellipses of the photographs (which are 1.13 to
   1.4 times the object's size), is a loose axis-aligned ellipse around the object: centred
   on the reference mask's bounding box, semi-axes 1.25 times the box's half sizes, 200
   points.

``wheel-5spoke-redband`` is left out: from the top it is identical to ``wheel-5spoke``.
"""

from __future__ import annotations

import os

import numpy as np

from benchmarks.segmentation_cases import Case, ProviderUnavailable
from vision.segmentation import ellipse_contour

__all__ = ["DISTANCE_M", "INIT_SCALE", "WHEELS", "sim_cases"]

#: Wheel types rendered, with their yaw on the belt (degrees).
WHEELS: dict[str, float] = {
    "wheel-5spoke": 17.0,
    "wheel-7spoke-curved": -35.0,
    "wheel-10spoke-twin": 52.0,
    "wheel-steel": 8.0,
    "wheel-6spoke-split": -71.0,
}
#: Semi-axes of the initial ellipse over the half sizes of the object's bounding box.
INIT_SCALE = 1.25
#: Camera distance above the wheel's top face, metres.
DISTANCE_M = 0.55


def sim_cases(n_points: int = 200) -> list[Case]:
    """Top views of wheels on the belt from the eye-in-hand camera (module docstring).

    Raises :class:`ProviderUnavailable` when MuJoCo cannot be imported or cannot render
    (e.g. no EGL / OSMesa).
    """
    os.environ.setdefault("MUJOCO_GL", "egl")
    try:
        from robot.sim import CATALOGUE, SimEngine
        from robot.sim.imaging import capture, object_masks
        from robot.sim.poses import viewpoint
    except Exception as exc:  # ImportError, or MuJoCo failing to load its GL backend
        raise ProviderUnavailable(f"robot.sim cannot be imported: {exc}") from exc
    engine = SimEngine()
    try:
        belt = engine.config.layout.conveyor
        cases = []
        for name, yaw_deg in WHEELS.items():
            engine.clear_objects()
            obj = engine.spawn(name, s_m=belt.station_s_m, yaw_rad=np.radians(yaw_deg))
            top = CATALOGUE[name].geometry().bounds[1, 2]
            q = viewpoint(
                belt.station_point + np.array([0.0, 0.0, top]), "top", distance_m=DISTANCE_M
            )
            try:
                shot = capture(engine, q)
                mask = object_masks(engine, shot.snapshot, ids=[obj.id])[obj.id]
            except RuntimeError as exc:  # the render thread could not make a GL context
                raise ProviderUnavailable(f"MuJoCo rendering failed: {exc}") from exc
            if not mask.any():
                raise ProviderUnavailable(f"{name} is not in the camera's view")
            ys, xs = np.nonzero(mask)
            centre = ((xs.min() + xs.max()) / 2.0, (ys.min() + ys.max()) / 2.0)
            axes = (
                INIT_SCALE * (xs.max() - xs.min() + 1) / 2.0,
                INIT_SCALE * (ys.max() - ys.min() + 1) / 2.0,
            )
            init = ellipse_contour(centre, axes, n_points=n_points)
            h, w = mask.shape
            if init.min() < 0 or init[:, 0].max() > w - 1 or init[:, 1].max() > h - 1:
                raise ProviderUnavailable(f"the initial ellipse of {name} leaves the image")
            cases.append(
                Case(
                    name=name.removeprefix("wheel-"),
                    provider="sim",
                    description=f"wheel: {CATALOGUE[name].description.split(',')[0]}",
                    image=shot.rgb,
                    reference=mask,
                    init=init,
                )
            )
        return cases
    finally:
        engine.stop()
