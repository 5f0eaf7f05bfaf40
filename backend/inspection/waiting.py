"""Waiting for a part, and which part is next on an indexing belt.

A run that finds the station empty waits for a part: that is not an inspection, so it
leaves no row behind.  Its job's progress says what it waits for and what the belt does
(:func:`waiting_message`), from the belt's own report (:func:`belt_status`) when the cell
has a conveyor it can read.

On an indexing belt the station is seldom seen empty between two parts: the top view sees
more belt than the parts' spacing, so a neighbour is always in view.  Which part is new is
told by where it rides on the belt instead (:class:`PartTracker`): its *belt coordinate*,
the position of its centre along the belt's travel minus the belt's encoder travel at the
exposure, is fixed to the belt.  Parts upstream of the last one inspected have a smaller
coordinate; the one inspected, still held at the station, has the same one.  A part taken
off the belt at the end and put back at its entry (a loop) comes back with a coordinate one
loop smaller, so it counts as new, as it should.  A part put by hand where the last one
stood, the belt still, has its coordinate: its region in the top view tells it apart (a
part of another shape or turned otherwise).  When the station is seen empty, any part that
comes is new.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from robot.drivers.conveyor import BeltStatus, Conveyor
from vision.errors import Conflict
from vision.segmentation import iou

if TYPE_CHECKING:
    from backend.runtime import CellRuntime

__all__ = [
    "PartTracker",
    "belt_status",
    "conveyor_of",
    "describe",
    "require_conveyor",
    "waiting_message",
]

#: Two parts seen at the station are one and the same when their belt coordinates are
#: closer than this, metres (parts on a belt are never this close: they would touch) ...
SAME_PART_M = 0.06
#: ... and their regions in the top view overlap by at least this (intersection over union).
SAME_REGION_IOU = 0.8


def conveyor_of(rt: CellRuntime) -> Conveyor | None:
    """The cell's conveyor when it can read and start it, else None (a fixed station)."""
    c = rt.conveyor
    return c if c.controllable else None


def belt_status(rt: CellRuntime) -> BeltStatus | None:
    """The belt's state now, or None when the cell has no conveyor it can read."""
    c = conveyor_of(rt)
    return None if c is None else c.status()


def require_conveyor(rt: CellRuntime) -> Conveyor:
    """The conveyor, or :class:`Conflict` (409) when the cell has none it can start."""
    c = conveyor_of(rt)
    if c is None:
        raise Conflict("this cell has no conveyor it can start or stop: move the parts by hand")
    return c


def describe(status: BeltStatus | None) -> str:
    """One line about the belt for an operator."""
    if status is None:
        return "no belt the cell can read: put a part at the station"
    objs = "" if status.objects is None else f", {status.objects} object(s) on it"
    if status.halted:
        return f"belt halted by the emergency stop{objs}: reset the cell"
    if not status.running:
        hint = ": start the belt" if status.objects != 0 else ": put a part on it"
        return f"belt stopped{objs}{hint}"
    return f"belt running ({status.mode}, {status.speed_m_s:g} m/s){objs}"


def waiting_message(status: BeltStatus | None, *, same_part: bool = False) -> str:
    """The job's progress while a run waits (``same_part``: the part at the station is
    the one just inspected, waiting for the belt to bring the next)."""
    what = "waiting for the next part" if same_part else "waiting for a part"
    return f"{what} at the station: {describe(status)}"


@dataclass
class PartTracker:
    """Which part an indexing run inspected last (module docstring).

    Attributes
    ----------
    last_u : float or None
        Belt coordinate of the last part inspected, metres (None: none yet, or forgotten).
    last_mask : ndarray of shape (H, W), bool, or None
        Its region in the top view when it was found.
    """

    last_u: float | None = None
    last_mask: NDArray[np.bool_] | None = None

    def is_new(self, u: float, mask: NDArray[np.bool_] | None = None) -> bool:
        """Whether a part at belt coordinate ``u``, seen as ``mask`` in the top view, is not
        the last one inspected: another coordinate, or at the same one another region (a
        part put by hand where the last one stood, on a belt that did not move)."""
        if self.last_u is None or not math.isfinite(u):
            return True
        if abs(u - self.last_u) >= SAME_PART_M:
            return True
        if mask is None or self.last_mask is None or mask.shape != self.last_mask.shape:
            return False
        return iou(mask, self.last_mask) < SAME_REGION_IOU

    def inspected(self, u: float | None, mask: NDArray[np.bool_] | None = None) -> None:
        """Note the part just inspected (``u`` None or NaN: nothing to note)."""
        if u is not None and math.isfinite(u):
            self.last_u = float(u)
            self.last_mask = None if mask is None else np.asarray(mask, dtype=bool)

    def station_empty(self) -> None:
        """The station was seen empty: any part that comes is new."""
        self.last_u = None
        self.last_mask = None
