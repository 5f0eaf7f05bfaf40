"""The camera poses sampled by a cell's current (or last) automatic calibration run."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from backend.cell.events import CalibrationView

__all__ = ["CalibrationViewLog"]


class CalibrationViewLog:
    """The sampled camera poses of one cell, for the 3D view (owned by the cell).

    Listeners get ``("clear", None)`` when a run starts and ``("view", (T_base_cam, ok))``
    for each stored sample (``ok``: the board was found); each change is also published as
    a :class:`~backend.cell.events.CalibrationView` event when ``publish`` is given.
    """

    def __init__(self, publish: Callable[[CalibrationView], None] | None = None) -> None:
        self.poses: list[tuple[NDArray[np.float64], bool]] = []
        self._listeners: list[Callable[[str, Any], None]] = []
        self._publish = publish

    def add_listener(self, fn: Callable[[str, Any], None]) -> None:
        """Call ``fn(event, data)`` on every change."""
        self._listeners.append(fn)

    def remove_listener(self, fn: Callable[[str, Any], None]) -> None:
        """Stop calling ``fn``."""
        if fn in self._listeners:
            self._listeners.remove(fn)

    def _emit(self, event: str, data: Any) -> None:
        for fn in list(self._listeners):
            fn(event, data)

    def clear(self) -> None:
        """A new run starts."""
        self.poses = []
        self._emit("clear", None)
        if self._publish is not None:
            self._publish(CalibrationView(cleared=True))

    def add(self, T_base_cam: NDArray[np.float64], ok: bool) -> None:
        """A sample was stored (``T_base_cam``: 4x4 camera pose, metres)."""
        T = np.array(T_base_cam, dtype=np.float64)
        self.poses.append((T, ok))
        self._emit("view", (T, ok))
        if self._publish is not None:
            self._publish(CalibrationView(cleared=False, T_base_cam=T, board_found=bool(ok)))
