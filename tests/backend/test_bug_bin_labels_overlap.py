"""The bins' names in the 3D view (and so in the recorded replay) used to sit at one height
and ran into each other: neighbouring bins are 0.3 m apart, bins one behind the other show
their labels side by side.  Seen from the view's first camera, no label covers another now."""

from __future__ import annotations

import math

import numpy as np

from backend.cell.events import EventBus
from backend.view3d.inspections import (
    LABEL_CHAR_PX,
    LABEL_LINE_PX,
    LABEL_SCALE,
    InspectionScene,
    LabelCamera,
    bin_label,
    label_heights,
)
from backend.view3d.server import EMBEDDED_VIEW_PX, INITIAL_CAMERA_M, INITIAL_LOOK_AT_M
from robot.sim.bins import default_bins

FIRST_VIEW = LabelCamera(INITIAL_CAMERA_M, INITIAL_LOOK_AT_M, fov_rad=math.radians(75.0),
                         height_px=EMBEDDED_VIEW_PX)  # fmt: skip


def _boxes(bins, heights):
    out = []
    for b, h in zip(bins, heights, strict=True):
        u, v = FIRST_VIEW.project(np.array([*b.centre_xy, b.rim_z_m + h]))
        w = len(bin_label(b)) * LABEL_CHAR_PX * LABEL_SCALE
        out.append((u - w / 2, v - LABEL_LINE_PX * LABEL_SCALE, u + w / 2, v))
    return out


def _overlapping(boxes):
    return [
        (i, j)
        for i, a in enumerate(boxes)
        for j, b in enumerate(boxes[:i])
        if min(a[2], b[2]) > max(a[0], b[0]) and min(a[3], b[3]) > max(a[1], b[1])
    ]


def test_one_height_overlaps_and_the_layout_does_not():
    bins = default_bins()
    assert _overlapping(_boxes(bins, [0.05] * len(bins)))  # the old layout
    heights = label_heights(bins, FIRST_VIEW)
    assert _overlapping(_boxes(bins, heights)) == []
    assert min(heights) > 0 and max(heights) < 1.25  # above the rim, bounded


def test_the_scene_draws_each_label_at_its_height_with_a_leader():
    calls = []

    class _Scene:
        def __getattr__(self, kind):
            def add(name, *a, **k):
                calls.append((kind, name, k))
                return type("H", (), {"remove": lambda self: None})()

            return add

    server = type("S", (), {"scene": _Scene()})()
    bins = default_bins()
    scene = InspectionScene(server, EventBus(), bins, fov_rad=1.0, aspect=4 / 3,
                            labels_for=FIRST_VIEW)  # fmt: skip
    labels = {n: k for kind, n, k in calls if kind == "add_label"}
    heights = label_heights(bins, FIRST_VIEW)
    for b, h in zip(bins, heights, strict=True):
        k = labels[f"/inspection/bins/{b.name}/label"]
        assert math.isclose(k["position"][2], b.rim_z_m / 2 + h)
        assert k["anchor"] == "bottom-center"
    leaders = {n for kind, n, _ in calls if kind == "add_line_segments"}
    assert leaders == {
        f"/inspection/bins/{b.name}/leader" for b, h in zip(bins, heights, strict=True) if h > 0.05
    }
    scene.close()
