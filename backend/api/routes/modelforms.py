"""The bodies and parameters of the object model routes (:mod:`backend.api.routes.models`
and :mod:`backend.api.routes.views`): what a request may hold and what an answer holds."""

from __future__ import annotations

import math
from datetime import datetime
from typing import Annotated, Any, Literal

from fastapi import Path, Query
from pydantic import BaseModel, ConfigDict, Field

from backend import audit
from backend.recognition import models as svc
from backend.recognition import public
from backend.recognition import teach as teach_svc
from vision.errors import InvalidInput

#: Database integer keys are 32-bit signed on PostgreSQL.
DB_ID_MAX = 2**31 - 1
ModelId = Annotated[int, Path(ge=1, le=DB_ID_MAX, description="Object model id")]
ViewId = Annotated[int, Path(ge=1, le=DB_ID_MAX, description="Trained view id")]
Name = Annotated[str, Field(min_length=1, max_length=64, pattern=svc.NAME_PATTERN.pattern)]
#: Why a change is made (kept in the audit trail).
Reason = Annotated[
    str | None, Field(max_length=audit.MAX_REASON_LENGTH, description="Why (audit trail)")
]
ReasonQuery = Annotated[
    str | None, Query(max_length=audit.MAX_REASON_LENGTH, description="Why (audit trail)")
]


#: Height above the sitting base (what the pick plans with), shared by create and update.
HeightM = Annotated[
    float,
    Field(gt=0.0, le=0.5, allow_inf_nan=False,
          description="Height above the sitting base, metres (what the pick plans with)"),
]  # fmt: skip
#: The same height in millimetres (the console's and the CLI's unit); give one of the two.
HeightMm = Annotated[
    float,
    Field(gt=0.0, le=500.0, allow_inf_nan=False,
          description="Height above the sitting base, millimetres (instead of height_m)"),
]  # fmt: skip


def _height_fields(body: BaseModel, given: set[str]) -> dict[str, Any]:
    """``height_m`` from ``height_m`` or ``height_mm`` (not both), as given."""
    if "height_mm" not in given:
        return {"height_m": body.height_m} if "height_m" in given else {}  # type: ignore[attr-defined]
    if "height_m" in given:
        raise InvalidInput("give height_m or height_mm, not both")
    mm = body.height_mm  # type: ignore[attr-defined]
    return {"height_m": None if mm is None else float(mm) / 1000.0}


#: Suction point on the part's upper surface in the object frame, shared by create and update.
GraspObj = Annotated[
    list[Annotated[float, Field(ge=-0.5, le=0.5, allow_inf_nan=False)]],
    Field(min_length=3, max_length=3,
          description="Suction point on the upper surface, object frame [x, y, z], metres"),
]  # fmt: skip


class ModelCreate(BaseModel):
    """A new object model."""

    model_config = ConfigDict(extra="forbid", strict=True)

    name: Name
    part: Name | None = Field(None, description="Physical part (default: the name)")
    sitting_base: Name = "default"
    kind: Literal["2d", "3d"] = Field(description="2d: top view only; 3d: side views too")
    threshold: float | None = Field(
        None, ge=0.0, le=1.0, allow_inf_nan=False, description="Own score threshold"
    )
    description: str = Field("", max_length=2000)
    height_m: HeightM | None = None
    height_mm: HeightMm | None = None
    grasp_obj: GraspObj | None = None
    reason: Reason = None


class ModelUpdate(BaseModel):
    """Fields to change (absent ones keep their value; ``threshold: null`` clears it)."""

    model_config = ConfigDict(extra="forbid", strict=True)

    name: Name | None = None
    part: Name | None = None
    sitting_base: Name | None = None
    kind: Literal["2d", "3d"] | None = None
    threshold: float | None = Field(None, ge=0.0, le=1.0, allow_inf_nan=False)
    description: str | None = Field(None, max_length=2000)
    height_m: HeightM | None = None
    height_mm: HeightMm | None = None
    grasp_obj: GraspObj | None = None
    reason: Reason = None


class ModelPublic(public.ModelPublic):
    """An object model with its views counted in the database and in the live index."""

    # The API has always written this time as pydantic does (``...Z``), the CLI and the
    # teach result as ``isoformat()`` does (``...+00:00``); both stay as they are.
    created_at: datetime  # type: ignore[assignment]
    indexed_views: int = Field(description="Views in the live index")
    stale_views: int = Field(description="Views refused by the index (stale features)")


class ModelList(BaseModel):
    data: list[ModelPublic]
    count: int


class ViewPublic(public.ViewPublic):
    """A trained view with what the live index made of it."""

    # Written as pydantic does (``...Z``), as the API always has (see ModelPublic).
    created_at: datetime  # type: ignore[assignment]
    indexed: bool = Field(description="The view is in the live index")
    stale: str | None = Field(description="Why the index refused the view, if it did")


class ViewList(BaseModel):
    data: list[ViewPublic]
    count: int


class TeachIn(BaseModel):
    """Options of a teach (see ``backend.recognition.teach.TeachOptions``)."""

    model_config = ConfigDict(extra="forbid", strict=True)

    viewpoints: list[int] | None = Field(
        None, min_length=1, max_length=3, description="Default: [1] for 2d, [1, 2, 3] for 3d"
    )
    top_rolls_rad: list[float] | None = Field(
        None, min_length=1, max_length=12, description="Camera rolls of the top view, rad"
    )
    background: Literal["grab", "stored"] = Field(
        "grab",
        description="grab: the station must be empty; the job grabs the background, then "
        "waits for the object. stored: the backgrounds of an earlier teach",
    )
    object_height_m: float = Field(0.1, gt=0.0, le=0.5, allow_inf_nan=False)
    yaw_rad: float = Field(0.0, ge=-math.pi, le=math.pi, allow_inf_nan=False)
    speed: float | None = Field(None, gt=0.0, le=1.0, allow_inf_nan=False)
    wait_s: float = Field(120.0, ge=0.0, le=teach_svc.MAX_WAIT_S, allow_inf_nan=False)
    replace: bool = Field(False, description="Replace the model's earlier views")
    threshold: bool = Field(
        True,
        description="Choose the automatic threshold at the end (false: a later round of the "
        "same teach chooses it; the threshold in force stays meanwhile)",
    )
    point: list[float] | None = Field(
        None, min_length=3, max_length=3, description="Station point x, y, z in metres"
    )
    reason: Reason = None
