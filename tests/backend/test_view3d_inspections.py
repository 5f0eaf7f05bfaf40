"""The 3D view's drawing of inspections: bins once, each inspection replacing the last."""

from __future__ import annotations

import numpy as np

from backend.cell.events import EventBus, InspectionDone
from backend.view3d.inspections import InspectionScene
from robot.sim.bins import default_bins


class _Handle:
    def __init__(self, log, name):
        self.log, self.name = log, name
        log.append(("add", name))

    def remove(self):
        self.log.append(("remove", self.name))


class _Scene:
    def __init__(self):
        self.log = []

    def __getattr__(self, kind):
        return lambda name, *a, **k: _Handle(self.log, name)


class _Server:
    def __init__(self):
        self.scene = _Scene()


def _event(i, decision="recognized", pose=True):
    T = np.eye(4)
    T[:3, 3] = (0.8, 0.0, 0.45)
    return InspectionDone(
        i, decision, "gear-housing" if decision == "recognized" else None, "why", 0.5, (1, 2),
        tuple(map(tuple, T)) if pose else None, (tuple(map(tuple, np.eye(4))),) * 2,
    )  # fmt: skip


def test_bins_and_inspections_are_drawn_and_replaced():
    server, bus = _Server(), EventBus()
    bins = default_bins()
    scene = InspectionScene(server, bus, bins, fov_rad=1.0, aspect=4 / 3)
    names = [n for op, n in server.scene.log if op == "add"]
    assert all(f"/inspection/bins/{b.name}" in names for b in bins)
    server.scene.log.clear()
    bus.publish(_event(1))
    added = [n for op, n in server.scene.log if op == "add"]
    assert "/inspection/object" in added and "/inspection/object/label" in added
    assert sum(n.startswith("/inspection/views/") for n in added) == 2
    server.scene.log.clear()
    bus.publish(_event(2, "unknown", pose=False))
    removed = [n for op, n in server.scene.log if op == "remove"]
    assert "/inspection/object" in removed and scene.last.inspection_id == 2
    scene.close()
    server.scene.log.clear()
    bus.publish(_event(3))
    assert server.scene.log == []
