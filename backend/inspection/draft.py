"""One inspection's result while it is made: :class:`InspectionDraft`, filled by the stages
(:mod:`backend.inspection.stages`) and turned into the stored record and the live event in
one place (:mod:`backend.inspection.record`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from backend.inspection.results import ViewRecord
from backend.inspection.stopwatch import Stopwatch

__all__ = ["InspectionDraft"]


@dataclass(eq=False)
class InspectionDraft:
    """What one inspection has found so far (a ``failed`` one until it decides)."""

    #: The part's belt coordinate as found (:mod:`backend.inspection.waiting`; NaN: none).
    u_m: float = float("nan")
    decision: str = "failed"
    reason: str = ""
    model: str | None = None
    model_id: int | None = None
    score: float | None = None
    #: Every model's fused score.
    scores: dict[str, float] = field(default_factory=dict)
    viewpoints: tuple[int, ...] = ()
    #: The pose's public form (None: no pose).
    pose: dict[str, Any] | None = None
    pick: dict[str, Any] | None = None
    #: The simulator's object nearest the part (evaluation only; never read by decisions).
    truth: dict[str, Any] | None = None
    #: The stage running, for the reason of a cut-short inspection (None: not begun).
    stage: str | None = None
    #: Where the top view found the part on the belt's surface (base frame, metres).
    found: NDArray[np.float64] | None = None
    #: The part's footprint radius, metres (its obstacle box for a pick).
    radius: float = 0.18
    light_gain: list[float] | None = None
    #: The images stored with the row, and the camera poses of the views taken.
    views: list[ViewRecord] = field(default_factory=list)
    cams: list[NDArray[np.float64]] = field(default_factory=list)
    #: The 3D scene recorder (:class:`backend.reports.scenes.SceneRecorder`; None: none).
    scene: Any = None
    watch: Stopwatch = field(default_factory=Stopwatch)

    def note(self, text: str) -> None:
        """Add ``text`` to the reason (after ``"; "`` when there is one)."""
        self.reason = f"{self.reason}; {text}" if self.reason else text

    def fail(self, reason: str) -> None:
        self.decision, self.reason = "failed", reason
