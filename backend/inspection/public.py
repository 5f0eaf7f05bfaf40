"""The public shape of a stored inspection: what the API answers, the live event carries
and the PLC reads (:func:`backend.inspection.results.inspection_public`)."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, Field

from backend.db.models import Inspection
from backend.publictypes import IsoTime

__all__ = ["InspectionPublic", "PickOutcome"]


class PickOutcome(BaseModel):
    """What happened to the object (:func:`backend.inspection.results.pick_outcome`)."""

    outcome: Literal["placed", "rejected", "not_placed", "approach", "not_picked", "not_sorted"]
    bin: str | None = Field(description="The bin it went to (or was meant for)")
    text: str = Field(description="A sentence for the operator")


class InspectionPublic(BaseModel):
    """A stored inspection."""

    id: int
    cell_id: int
    started_at: IsoTime
    finished_at: IsoTime | None
    decision: Literal["recognized", "unknown", "failed"]
    reason: str = Field(description="Why it ended so (empty for a plain recognition)")
    policy: str = Field(description="The multi-view policy it followed")
    model: str | None = Field(description="Name of the recognised model")
    model_id: int | None
    score: float | None = Field(description="The recognised model's score")
    scores: dict[str, float] = Field(description="Model name -> score")
    viewpoints_visited: list[int] = Field(description="The viewpoints looked from, in order")
    pose: dict[str, Any] | None = Field(
        description="The object's pose; open because its form depends on how it was "
        "measured: in the cell, its pose on the belt (T_base_obj, position_m, the fit and "
        "the belt's motion); from an uploaded image, an image pose (frame image: position, "
        "angle, scale and outline in pixels)"
    )
    durations: dict[str, float] = Field(description="Seconds per stage")
    duration_s: float | None = Field(description="Seconds from start to end")
    pick: dict[str, Any] | None = Field(
        description="What the arm did after the decision as the sorting stage recorded it "
        "(open: its keys depend on whether it sorted, picked or only approached; "
        "pick_outcome says it in fixed form)"
    )
    pick_outcome: PickOutcome
    truth: dict[str, Any] | None = Field(
        description="The simulator's ground truth for the object (None on real hardware); "
        "open: what the simulator knows differs by object"
    )
    source: Literal["cell", "upload"] = Field(
        description="Where its images came from: the cell's camera or an uploaded image"
    )
    recipe_id: int | None
    recipe: str | None = Field(description="Name of the recipe it followed")
    images: list[str] = Field(description="URLs of the viewpoint images, in order")

    @classmethod
    def of(cls, row: Inspection, pick_outcome: PickOutcome, n_images: int) -> InspectionPublic:
        """The public form of a row with ``n_images`` stored images."""
        return cls(
            id=row.id,
            cell_id=row.cell_id,
            started_at=row.started_at,  # IsoTime writes it in ISO form
            finished_at=row.finished_at,
            decision=row.decision.value,
            reason=row.reason,
            policy=row.policy,
            model=row.model_name,
            model_id=row.model_id,
            score=row.score,
            scores=row.scores or {},
            viewpoints_visited=list(row.viewpoints_visited or []),
            pose=row.pose,
            durations=row.durations or {},
            duration_s=row.duration_s,
            pick=row.pick,
            pick_outcome=pick_outcome,
            truth=row.truth,
            source=row.source,
            recipe_id=row.recipe_id,
            recipe=row.recipe_name,
            images=[f"/api/inspections/{row.id}/images/{k}.jpg" for k in range(n_images)],
        )
