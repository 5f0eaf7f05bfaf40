"""What a cell's inspections keep between jobs: the belt background and the running run.

One :class:`InspectionState` lives on the :class:`~backend.runtime.CellRuntime` from its
construction (``rt.inspection``); the inspection service reads and replaces its fields,
nothing else does.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from backend.inspection.runner import InspectionRun
    from vision.segmentation.belt import BeltBackground

__all__ = ["InspectionState"]


@dataclass
class InspectionState:
    """The cell's inspection memory (module docstring)."""

    belt_background: BeltBackground | None = None
    """The top view's empty belt registered to its travel (``grab_belt_background``)."""
    run: InspectionRun | None = None
    """The continuous inspection run, if one was started (``start_run``)."""
