"""The catalogue: wheels, parts, a part with two sitting bases, untrainable parts."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from robot.sim import CATALOGUE, SimEngine
from robot.sim.catalogue import WHEELS
from robot.sim.imaging import Imager
from robot.sim.mjcf import texture_tint
from robot.sim.poses import viewpoint
from robot.sim.world import WorldLayout


def test_catalogue_has_the_required_objects():
    wheels = [e for e in CATALOGUE.values() if e.kind == "wheel"]
    parts = [e for e in CATALOGUE.values() if e.kind == "part"]
    assert len(wheels) >= 5
    designs = [WHEELS[w.name][1] for w in wheels]
    assert len({(d.spokes, d.style) for d in designs}) >= 5  # spoke count and shape differ
    assert len({d.bolts for d in designs}) >= 3
    assert len({d.width_m for d in designs}) >= 4
    assert len({d.sidewall_text for d in designs}) >= 5
    trainable_parts = {e.base_of for e in parts if e.trainable}
    assert len(trainable_parts) >= 4
    by_part: dict[str, list[str]] = {}
    for e in CATALOGUE.values():
        by_part.setdefault(e.base_of, []).append(e.name)
    assert ["bracket-upright", "bracket-flat"] in by_part.values()
    assert len([e for e in CATALOGUE.values() if not e.trainable]) >= 2


def test_every_entry_builds_procedural_geometry():
    for entry in CATALOGUE.values():
        geo = entry.geometry()
        b = geo.bounds
        assert b[0, 2] == pytest.approx(0.0, abs=1e-9), entry.name  # sits on the belt
        assert 0.05 < b[1, 2] < 0.2, entry.name  # tops near the station height
        assert np.all(b[1, :2] - b[0, :2] < 0.4), entry.name  # fits the belt
        for piece in geo.pieces:
            assert piece.material in geo.materials
        s = entry.summary()
        assert s["name"] == entry.name and s["trainable"] == entry.trainable


def test_the_two_sitting_bases_are_the_same_part_turned():
    up = CATALOGUE["bracket-upright"].geometry()
    flat = CATALOGUE["bracket-flat"].geometry()
    size_up = np.sort(up.bounds[1] - up.bounds[0])
    size_flat = np.sort(flat.bounds[1] - flat.bounds[0])
    np.testing.assert_allclose(size_up, size_flat, atol=1e-9)
    assert up.bounds[1, 2] != pytest.approx(flat.bounds[1, 2])  # a different height on the belt


@pytest.fixture(scope="module")
def views(engine: SimEngine):
    """Top and side renders of the two look-alike wheels at the station, same yaw."""
    st = engine.config.layout.conveyor.station_s_m
    station = engine.config.layout.conveyor.station_point + np.array([0.0, 0.0, 0.095])
    qs = {"top": viewpoint(station, "top"), "side": viewpoint(station, "inner", distance_m=0.65)}
    imager = Imager(engine.config.camera.with_(noise_std_dn=0.0))
    out: dict[tuple[str, str], np.ndarray] = {}
    for name in ("wheel-5spoke", "wheel-5spoke-redband"):
        engine.clear_objects()
        engine.spawn(name, s_m=st, yaw_rad=0.2)
        for view, q in qs.items():
            engine.set_joints(q)
            snap = engine.snapshot()
            out[(name, view)] = (
                engine.renderer().submit(lambda w, s=snap: imager.render(w, s)).result().rgb
            )
    engine.clear_objects()
    return out


def test_look_alike_wheels_are_identical_from_the_top(views):
    a = views[("wheel-5spoke", "top")].astype(float)
    b = views[("wheel-5spoke-redband", "top")].astype(float)
    assert np.abs(a - b).max() == 0.0


def test_look_alike_wheels_differ_from_the_side(views):
    a = views[("wheel-5spoke", "side")]
    b = views[("wheel-5spoke-redband", "side")]
    # Grey levels scale with the textures' tint (robot.sim.mjcf.texture_tint, 2/3 at the
    # default lights; the levels below were set at no tint): the tread is lit at a grazing
    # angle, below MuJoCo's clamp with or without the tint.
    k = texture_tint(WorldLayout())
    diff = np.abs(a.astype(float) - b.astype(float)).sum(axis=2)
    assert (diff > 60 * k).sum() > 500  # the red band and its lettering on the near tread

    def red(im: np.ndarray) -> int:  # the band is dark red at this grazing angle
        r, g = im[..., 0].astype(int), im[..., 1].astype(int)
        return int(((r > 2 * g + 20 * k) & (r > 60 * k)).sum())

    assert red(b) > red(a) + 250


def test_wheel_sidewall_lettering_is_readable_from_the_top(views):
    # The lettering is drawn lighter than the tyre: the tyre ring carries many light pixels.
    top = cv2.cvtColor(views[("wheel-5spoke", "top")], cv2.COLOR_RGB2GRAY)
    assert top.std() > 30
