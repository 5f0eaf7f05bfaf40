"""A synthetic conveyor seen from the top view at the station: dark belt with light cross
stripes moving with the travel, the floor beside it (the moving-belt regression tests)."""

from __future__ import annotations

import numpy as np

from backend.inspection.belt import BeltGeometry
from backend.inspection.pose import plane_points
from vision.camera import PinholeCamera

GEO = BeltGeometry(centre_x_m=0.8, start_y_m=-1.3, width_m=0.44, surface_z_m=0.45, loop_m=2.6)
PITCH = 2.6 / 9  # stripes evenly spaced round the loop, as the simulator's
CAM = PinholeCamera(np.array([[500.0, 0, 160], [0, 500.0, 120], [0, 0, 1]]), (0.0,) * 5)


def T_cam() -> np.ndarray:
    """Camera 0.4 m above the belt at the station, looking straight down (the belt runs
    up the image, across it is the image's x)."""
    T = np.eye(4)
    T[:3, :3] = np.diag([1.0, -1.0, -1.0])
    T[:3, 3] = (0.8, 0.0, 0.85)
    return T


def render(
    travel: float,
    box: tuple[float, float, float, float] | None = None,
    *,
    falloff: bool = False,
) -> np.ndarray:
    """The belt at ``travel`` (320 x 240 RGB); ``box`` = (x, y, half-width x, half-length
    y) on it, metres; ``falloff``: a light falling off across the view."""
    h, w = 240, 320
    ys, xs = np.mgrid[0:h, 0:w]
    px = np.stack([xs.ravel(), ys.ravel()], axis=1).astype(float)
    p = plane_points(px, CAM, T_cam(), GEO.surface_z_m).reshape(h, w, 3)
    u = np.mod(p[..., 1] - GEO.start_y_m - travel, GEO.loop_m)
    stripe = np.mod(u, PITCH) < 0.016
    on = np.abs(p[..., 0] - GEO.centre_x_m) < GEO.width_m / 2
    img = np.where(on, np.where(stripe, 110.0, 42.0), 150.0)
    if falloff:
        img = img * (0.8 + 0.2 * np.cos((xs - 160) / 300.0))
    img = np.repeat(img[..., None], 3, axis=2)
    if box is not None:
        x, y, hx, hy = box
        inside = (np.abs(p[..., 0] - x) < hx) & (np.abs(p[..., 1] - y) < hy)
        img[inside] = (30.0, 60.0, 170.0)
    return np.clip(img, 0, 255).astype(np.uint8)
