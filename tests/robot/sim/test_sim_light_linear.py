"""The rendered picture scales with the light: a part under half light is its normal picture
at half the level, as the belt round it is (``robot.sim.mjcf.texture_tint``).

Before the tint, MuJoCo's clamp of a textured face's lighting at 1 left the valve block's
top face at 1/1.38 of its normal level under half light while the belt fell to 1/2, so the
light balance of the inspection (a per-channel gain from the belt) could not bring the part
back: this test failed for every textured part with ratios of 1.3-1.5.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from robot.sim.catalogue import CATALOGUE
from robot.sim.imaging import capture, object_masks
from robot.sim.mjcf import texture_tint
from robot.sim.poses import viewpoint
from robot.sim.world import LightSpec, WorldLayout


def _textured(name: str) -> bool:
    return any(m.texture is not None for m in CATALOGUE[name].geometry().materials.values())


TEXTURED = [n for n in CATALOGUE if _textured(n)]


def _set_lights(engine, level: float) -> None:
    for light in engine.lights():
        engine.set_light(light, level)


@pytest.mark.parametrize("name", TEXTURED)
def test_a_textured_part_scales_with_the_light_as_the_belt_does(engine, name):
    belt = engine.config.layout.conveyor
    engine.clear_objects()
    obj = engine.spawn(name, s_m=belt.station_s_m, yaw_rad=math.radians(25.0))
    q = viewpoint(belt.station_point + np.array([0.0, 0.0, 0.1]), "top", distance_m=0.55)
    spec = engine.config.camera.with_(noise_std_dn=0.0)
    try:
        shots = {}
        for level in (1.0, 0.5):
            _set_lights(engine, level)
            shots[level] = capture(engine, q, spec=spec)
    finally:
        _set_lights(engine, 1.0)
    mask = object_masks(engine, shots[1.0].snapshot)[obj.id]
    # Away from the outline (the edge blends part and belt) and from pixels too dark for a
    # ratio or clipped at the normal level.
    inner = cv2.erode(mask.astype(np.uint8), np.ones((7, 7), np.uint8)).astype(bool)
    full = shots[1.0].rgb.astype(np.float64)
    half = shots[0.5].rgb.astype(np.float64)
    usable = inner[..., None] & (full >= 40.0) & (full < 250.0)
    assert usable.sum() > 500, f"{name}: only {usable.sum()} usable pixel values"
    part_ratio = np.median(full[usable] / np.maximum(half[usable], 1.0))
    around = ~cv2.dilate(mask.astype(np.uint8), np.ones((41, 41), np.uint8)).astype(bool)
    belt_ok = around[..., None] & (full >= 40.0) & (full < 250.0)
    belt_ratio = np.median(full[belt_ok] / np.maximum(half[belt_ok], 1.0))
    assert belt_ratio == pytest.approx(2.0, abs=0.06)
    assert part_ratio == pytest.approx(belt_ratio, abs=0.08), (
        f"{name}: the part's level fell by {part_ratio:.2f}, the belt's by {belt_ratio:.2f}"
    )


def test_the_tint_is_the_inverse_of_the_most_light_a_face_can_receive():
    layout = WorldLayout()
    bound = layout.ambient + sum(s.diffuse for s in layout.lights)
    assert texture_tint(layout) == pytest.approx(1.0 / bound)
    dim = WorldLayout(lights=(LightSpec("only", (0.0, 0.0, 3.0), (0.0, 0.0, -1.0), 0.3),))
    assert texture_tint(dim) == 1.0  # 0.3 ambient + 0.3: never clamped, no tint
