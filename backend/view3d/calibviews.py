"""Camera poses sampled by an automatic calibration run, drawn as frusta in the 3D view.

Follows the cell's :class:`~backend.cell.viewlog.CalibrationViewLog` (``cell.calibration_views``): a run's start clears
the previous run's frusta, each stored sample adds one (green: board found, red: not).
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np
import viser
import viser.transforms as vtf

from backend.cell.viewlog import CalibrationViewLog

__all__ = ["CalibrationFrusta"]

log = logging.getLogger(__name__)

FOUND = (40, 170, 70)
MISSED = (200, 50, 50)


class CalibrationFrusta:
    """Frusta of the sampled camera poses under ``/calibration/views``.

    Parameters
    ----------
    server : viser.ViserServer
    views : CalibrationViewLog
        The cell's log of sampled poses (``T_base_cam``).
    fov_rad, aspect : float
        Vertical field of view and aspect ratio of the drawn frusta.
    """

    def __init__(
        self, server: viser.ViserServer, views: CalibrationViewLog, *, fov_rad: float, aspect: float
    ) -> None:
        self.server = server
        self.views = views
        self.fov_rad = fov_rad
        self.aspect = aspect
        self.handles: list[Any] = []
        for T, ok in views.poses:  # a run that started before the view did
            self._add(T, ok)
        views.add_listener(self._on_event)

    def close(self) -> None:
        """Stop following the log (the frusta stay until the server stops)."""
        self.views.remove_listener(self._on_event)

    def _on_event(self, event: str, data: Any) -> None:
        try:
            if event == "clear":
                for h in self.handles:
                    h.remove()
                self.handles = []
            elif event == "view":
                T, ok = data
                self._add(T, ok)
        except Exception:  # the 3D view must never break a calibration run
            log.exception("cannot draw a calibration view")

    def _add(self, T_base_cam: np.ndarray, ok: bool) -> None:
        T = np.asarray(T_base_cam, dtype=np.float64)
        h = self.server.scene.add_camera_frustum(
            f"/calibration/views/{len(self.handles):03d}",
            fov=self.fov_rad,
            aspect=self.aspect,
            scale=0.05,
            color=FOUND if ok else MISSED,
            wxyz=vtf.SO3.from_matrix(T[:3, :3]).wxyz,
            position=T[:3, 3],
        )
        self.handles.append(h)
