"""The latest inspection in the 3D view (issue 14, part 7): the sorting bins, the recognised
object at its estimated pose with its label and decision, and the viewpoints visited as frusta.

Follows the cell's event bus (:class:`backend.inspection.service.InspectionDone`); each
inspection replaces the previous one's drawing.  Everything lives under ``/inspection``.
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np
import viser
import viser.transforms as vtf

from backend.inspection.service import InspectionDone

__all__ = ["InspectionScene"]

log = logging.getLogger(__name__)

COLOURS = {"recognized": (40, 170, 70), "unknown": (230, 160, 30), "failed": (200, 50, 50)}


class InspectionScene:
    """Draws the bins once and each inspection's result (module docstring).

    Parameters
    ----------
    server : viser.ViserServer
    bus : EventBus
        The cell's bus.
    bins : sequence of BinSpec
        The sorting bins (the simulator's layout; empty without one).
    fov_rad, aspect : float
        Of the drawn frusta.
    """

    def __init__(self, server: viser.ViserServer, bus: Any, bins: Any = (), *, fov_rad: float,
                 aspect: float) -> None:  # fmt: skip
        self.server = server
        self.fov_rad, self.aspect = fov_rad, aspect
        self.handles: list[Any] = []
        self.last: InspectionDone | None = None
        for b in bins:
            x, y = b.centre_xy
            c = (120, 120, 130) if not b.reject else (170, 60, 60)
            server.scene.add_box(
                f"/inspection/bins/{b.name}", color=c, dimensions=(b.size_m, b.size_m, b.rim_z_m),
                wxyz=vtf.SO3.from_z_radians(b.yaw_rad).wxyz, position=(x, y, b.rim_z_m / 2),
                opacity=0.35,
            )  # fmt: skip
            server.scene.add_label(f"/inspection/bins/{b.name}/label", b.name,
                                   position=(0.0, 0.0, b.rim_z_m / 2 + 0.05))  # fmt: skip
        self._remove = bus.add_listener(self._on_event, InspectionDone)

    def close(self) -> None:
        """Stop following the bus."""
        self._remove()

    def _on_event(self, event: InspectionDone) -> None:
        try:
            self.draw(event)
        except Exception:  # the 3D view must never break an inspection
            log.exception("cannot draw inspection %s", event.inspection_id)

    def draw(self, ev: InspectionDone) -> None:
        """Replace the drawing with inspection ``ev``."""
        for h in self.handles:
            h.remove()
        self.handles = []
        self.last = ev
        colour = COLOURS.get(ev.decision, (200, 200, 200))
        scene = self.server.scene
        for k, T in enumerate(ev.T_base_cams):
            Tm = np.asarray(T, dtype=np.float64)
            self.handles.append(scene.add_camera_frustum(
                f"/inspection/views/{k}", fov=self.fov_rad, aspect=self.aspect, scale=0.06,
                color=colour, wxyz=vtf.SO3.from_matrix(Tm[:3, :3]).wxyz, position=Tm[:3, 3],
            ))  # fmt: skip
        text = f"#{ev.inspection_id} {ev.decision}" + (f": {ev.model}" if ev.model else "")
        if ev.T_base_obj is not None:
            Tm = np.asarray(ev.T_base_obj, dtype=np.float64)
            frame = scene.add_frame("/inspection/object", axes_length=0.1, axes_radius=0.004,
                                    wxyz=vtf.SO3.from_matrix(Tm[:3, :3]).wxyz, position=Tm[:3, 3])  # fmt: skip
            self.handles.append(frame)
            self.handles.append(
                scene.add_label("/inspection/object/label", text, position=(0, 0, 0.2))
            )
        elif ev.T_base_cams:
            p = np.asarray(ev.T_base_cams[0], dtype=np.float64)[:3, 3]
            self.handles.append(
                scene.add_label("/inspection/label", text, position=p + np.array([0.0, 0.0, 0.1]))
            )
