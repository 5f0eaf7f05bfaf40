"""Inspecting objects at the station: the entry points, in one place for callers.

One inspection (:func:`inspect_object`, :mod:`backend.inspection.inspect`) is a pipeline
of stages, each filling one :class:`~backend.inspection.draft.InspectionDraft`:

1. **find** (:mod:`backend.inspection.find`): the top view at the station, planned as a
   teach plans it (:mod:`backend.planning`), so the teach's empty-belt background applies;
   the part that lies still there (index mode) or the frame of the moving part nearest
   the station (constant speed);
2. **look** and **recognise** (:mod:`backend.inspection.look`,
   :mod:`backend.inspection.recognise`): the top view segmented, side viewpoints planned
   where it found the part, the views recognised and the decision made;
3. **pose** (:mod:`backend.inspection.pose`, :mod:`backend.inspection.secondtop`);
4. **sort** (:mod:`backend.inspection.sort`): the part's bin, or only the approach pose;
5. **record** (:mod:`backend.inspection.record`): the stored row and the live
   :class:`~backend.cell.events.InspectionDone`, from the draft.

What it reads once is :mod:`backend.inspection.context`; its options are
:mod:`backend.inspection.options`; jobs and continuous operation are
:mod:`backend.inspection.runner`; the empty-belt backgrounds
:mod:`backend.inspection.background`.
"""

from __future__ import annotations

from backend.inspection.background import (
    grab_background,
    grab_belt_background,
    start_belt_background,
)
from backend.inspection.context import context
from backend.inspection.inspect import inspect_object
from backend.inspection.options import MAX_COUNT, MAX_WAIT_S, InspectOptions, Resolve
from backend.inspection.runner import (
    InspectionRun,
    hold_until_ready,
    readiness,
    start_inspection,
    start_run,
    stop_run,
)

__all__ = ["MAX_COUNT", "MAX_WAIT_S", "InspectOptions", "InspectionRun", "Resolve", "context",
           "grab_background", "grab_belt_background", "hold_until_ready", "inspect_object",
           "readiness", "start_belt_background", "start_inspection", "start_run", "stop_run"]  # fmt: skip
