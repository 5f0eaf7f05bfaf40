"""The latest inspection in the 3D view: the sorting bins, the recognised
object at its estimated pose with its label and decision, and the viewpoints visited as frusta.

Follows the cell's event bus (:class:`backend.cell.events.InspectionDone`); each
inspection replaces the previous one's drawing.  Everything lives under ``/inspection``.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import viser
import viser.transforms as vtf
from numpy.typing import NDArray

from backend.cell.events import InspectionDone

__all__ = ["InspectionScene", "LabelCamera", "bin_label", "label_heights"]

log = logging.getLogger(__name__)

COLOURS = {"recognized": (40, 170, 70), "unknown": (230, 160, 30), "failed": (200, 50, 50)}

#: Height of the lowest label above its bin's rim, and the step between levels, metres.
LABEL_BASE_M = 0.05
LABEL_STEP_M = 0.05
#: Most levels tried before a label takes the least crowded one.
LABEL_MAX_LEVELS = 24
#: Size of a bin's label relative to viser's default label text (kept on screen).
LABEL_SCALE = 0.8
#: viser's label text at scale 1: width of a character and height of a line (with its
#: padding), CSS pixels; a little over the measured size, so neighbours keep a gap.
LABEL_CHAR_PX = 8.0
LABEL_LINE_PX = 19.0


@dataclass(frozen=True)
class LabelCamera:
    """The view the bins' labels are laid out for (a pinhole, z up)."""

    eye_m: tuple[float, float, float]
    """Where the camera stands, base frame, metres."""
    target_m: tuple[float, float, float]
    """The point it looks at, base frame, metres."""
    fov_rad: float
    """Vertical field of view, radians."""
    height_px: float
    """Height of the viewport the labels are drawn in, CSS pixels (the smaller, the more
    room each label takes)."""

    def project(self, p_m: NDArray[np.float64]) -> tuple[float, float]:
        """Pixel position ``(u, v)`` of point ``p_m`` relative to the viewport's centre
        (v downwards)."""
        eye = np.asarray(self.eye_m, dtype=np.float64)
        f = np.asarray(self.target_m, dtype=np.float64) - eye
        f /= np.linalg.norm(f)
        r = np.cross(f, (0.0, 0.0, 1.0))
        r /= np.linalg.norm(r)
        up = np.cross(r, f)
        d = np.asarray(p_m, dtype=np.float64) - eye
        depth = max(float(d @ f), 1e-6)
        focal = 0.5 * self.height_px / math.tan(0.5 * self.fov_rad)
        return focal * float(d @ r) / depth, -focal * float(d @ up) / depth


def label_heights(
    bins: Any, camera: LabelCamera, *, base_m: float = LABEL_BASE_M,
    step_m: float = LABEL_STEP_M, scale: float = LABEL_SCALE,
) -> tuple[float, ...]:  # fmt: skip
    """Height of each bin's label above its rim, metres, so that seen from ``camera`` no
    two labels cover each other.

    Neighbouring bins are 0.3 m apart and their names up to 20 characters long, and bins
    one behind the other show their labels side by side: at one height they ran into each
    other.  Greedy: each bin, in order, takes the lowest level whose label (anchored at its
    bottom centre, its size estimated from the text) overlaps no label placed before.
    """
    placed: list[tuple[float, float, float, float]] = []
    out = []
    line = LABEL_LINE_PX * scale
    for b in bins:
        width = len(bin_label(b)) * LABEL_CHAR_PX * scale
        best: tuple[float, float, tuple[float, float, float, float]] | None = None
        for k in range(LABEL_MAX_LEVELS):
            h = base_m + step_m * k
            u, v = camera.project(np.array([*b.centre_xy, b.rim_z_m + h]))
            box = (u - width / 2, v - line, u + width / 2, v)
            overlap = sum(
                max(0.0, min(box[2], o[2]) - max(box[0], o[0]))
                * max(0.0, min(box[3], o[3]) - max(box[1], o[1]))
                for o in placed
            )
            if best is None or overlap < best[0]:
                best = (overlap, h, box)
            if overlap == 0.0:
                break
        assert best is not None
        placed.append(best[2])
        out.append(best[1])
    return tuple(out)


def bin_label(b: Any) -> str:
    """The text over a bin: its name without the ``bin-`` every bin's name starts with."""
    return str(b.name).removeprefix("bin-")


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
    labels_for : LabelCamera, optional
        The view's first camera: the bins' labels are stacked so that none covers another
        seen from it (:func:`label_heights`; without it, all at one height).
    """

    def __init__(self, server: viser.ViserServer, bus: Any, bins: Any = (), *, fov_rad: float,
                 aspect: float, labels_for: LabelCamera | None = None) -> None:  # fmt: skip
        self.server = server
        self.fov_rad, self.aspect = fov_rad, aspect
        self.handles: list[Any] = []
        self.last: InspectionDone | None = None
        bins = tuple(bins)
        heights = (label_heights(bins, labels_for) if labels_for is not None
                   else (LABEL_BASE_M,) * len(bins))  # fmt: skip
        for b, h in zip(bins, heights, strict=True):
            x, y = b.centre_xy
            c = (120, 120, 130) if not b.reject else (170, 60, 60)
            server.scene.add_box(
                f"/inspection/bins/{b.name}", color=c, dimensions=(b.size_m, b.size_m, b.rim_z_m),
                wxyz=vtf.SO3.from_z_radians(b.yaw_rad).wxyz, position=(x, y, b.rim_z_m / 2),
                opacity=0.35,
            )  # fmt: skip
            top = b.rim_z_m / 2
            server.scene.add_label(
                f"/inspection/bins/{b.name}/label", bin_label(b),
                position=(0.0, 0.0, top + h), anchor="bottom-center",
                font_screen_scale=LABEL_SCALE,
            )  # fmt: skip
            if h > LABEL_BASE_M:  # a raised label: a thin line shows whose it is
                server.scene.add_line_segments(
                    f"/inspection/bins/{b.name}/leader",
                    np.array([[[0.0, 0.0, top], [0.0, 0.0, top + h]]]), c, thickness=0.004,
                )  # fmt: skip
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
