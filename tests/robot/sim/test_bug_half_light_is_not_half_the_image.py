"""Regression (issue 14, half light and colour cast): the camera image must be linear in the
lights, as a real scene's radiance is.

MuJoCo's lighting clamps each fragment's summed light at 1 before the texture multiplies
it.  The cell's lights add up to about 1.5 on a face turned to them, so at their default
intensity most faces rendered flat at their texture colour, and halving every light scaled
an object's pixels by 0.67-0.73 (the gear housing) and the belt's by 0.53: not a change of
brightness, a change of shading, which the grey features and the colour signatures (made
to cancel a brightness or a diagonal colour change) could not undo.  The scene is now
rendered with the lights divided by ``LIGHT_HEADROOM`` and the sensor gains it back.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from robot.sim.imaging import capture, object_masks
from robot.sim.poses import viewpoint


def _lit_top_view(engine, scale: float):
    try:
        for light in engine.lights():
            engine.set_light(light, scale)
        belt = engine.config.layout.conveyor
        q = viewpoint(belt.station_point + np.array([0.0, 0.0, 0.1]), "top", distance_m=0.55)
        shot = capture(engine, q, spec=engine.config.camera.with_(noise_std_dn=0.0))
        return shot.rgb.astype(np.float64), shot.snapshot
    finally:
        for light in engine.lights():
            engine.set_light(light, 1.0)


@pytest.fixture()
def gear_housing(engine):
    engine.clear_objects()
    belt = engine.config.layout.conveyor
    obj = engine.spawn("gear-housing", s_m=belt.station_s_m, yaw_rad=math.radians(40.0))
    yield obj
    engine.clear_objects()


def _ratios(a: np.ndarray, b: np.ndarray, where: np.ndarray) -> np.ndarray:
    """Per-pixel ratio ``b / a`` of the lightly blurred images where ``a`` is well lit and
    not clipped (the 8-bit render's rounding stays under 3 %)."""
    a = cv2.GaussianBlur(a, (0, 0), 1.0)
    b = cv2.GaussianBlur(b, (0, 0), 1.0)
    m = where[..., None] if a.ndim == 3 else where
    ok = m & (a > 30.0) & (a < 250.0)
    return b[ok] / a[ok]


def test_half_light_scales_object_and_belt_by_one_half(engine, gear_housing):
    full, snap = _lit_top_view(engine, 1.0)
    half, _ = _lit_top_view(engine, 0.5)
    obj = object_masks(engine, snap)[gear_housing.id]
    for where in (obj, ~obj):
        r = _ratios(full, half, where)
        assert len(r) > 1000
        # Before the fix: object median 0.71 (10 %: 0.67), belt 0.53.
        assert np.percentile(r, [10, 50, 90]) == pytest.approx([0.5, 0.5, 0.5], abs=0.03)
