"""Recipes: named inspection configurations of the cell, and the active one.

Reading needs the viewer role; selecting the active recipe (a line changeover) the
operator role; creating, changing and deleting recipes the engineer role.  The work is in
:mod:`backend.recipes`; handlers only parse, call it and shape the answer.
"""

from __future__ import annotations

from datetime import datetime
from typing import Annotated, Any, Literal

from fastapi import APIRouter, Path, Query, status
from pydantic import BaseModel, ConfigDict, Field

from backend import audit
from backend.api.deps import EngineerUser, OperatorUser, RuntimeDep, ViewerUser
from backend.inspection.options import MAX_RECIPE_MODELS
from backend.recipes import service as svc
from backend.recipes.model import MAX_DESCRIPTION, MAX_NUMBER
from backend.recognition.models import NAME_PATTERN
from vision.errors import InvalidInput

__all__ = ["RecipeId", "router"]

router = APIRouter(prefix="/recipes", tags=["recipes"])

RecipeId = Annotated[int, Path(ge=1, le=2**31 - 1, description="Recipe id")]
Name = Annotated[str, Field(min_length=1, max_length=64, pattern=NAME_PATTERN.pattern)]
Number = Annotated[
    int,
    Field(ge=1, le=MAX_NUMBER, description="What a PLC selects the recipe by (unique per cell)"),
]
Policy = Literal["naive", "top-only", "two-views", "best-next"]
BeltMode = Literal["index", "continuous"]
Reason = Annotated[
    str | None, Field(max_length=audit.MAX_REASON_LENGTH, description="Why (audit trail)")
]
Models = Annotated[
    list[Name],
    Field(max_length=MAX_RECIPE_MODELS, description="Models in play (empty: every trained model)"),
]
Bins = Annotated[
    dict[Name, Name],
    Field(max_length=MAX_RECIPE_MODELS, description="Model name -> bin name it is sorted into"),
]
Threshold = Annotated[
    float | None,
    Field(ge=0.0, le=1.0, allow_inf_nan=False,
          description="Fixed global score threshold (null: the cell's, automatic or set)"),
]  # fmt: skip
Speed = Annotated[
    float | None,
    Field(gt=0.0, le=1.0, allow_inf_nan=False, description="Arm speed fraction (null: the cell's)"),
]
Description = Annotated[str, Field(max_length=MAX_DESCRIPTION)]


class RecipeCreate(BaseModel):
    """A new recipe (options left out take the inspection defaults)."""

    model_config = ConfigDict(extra="forbid", strict=True)

    name: Name
    number: Number
    description: Description = ""
    policy: Policy = "two-views"
    max_views: int = Field(3, ge=1, le=3)
    sort: bool = False
    threshold: Threshold = None
    belt_mode: BeltMode | None = Field(None, description="index or continuous (null: as it is)")
    speed: Speed = None
    balance_light: bool = True
    models: Models = []
    bins: Bins = {}
    reason: Reason = None


class RecipeUpdate(BaseModel):
    """Fields to change (absent ones keep their value; ``threshold``, ``belt_mode`` and
    ``speed`` may be set to null)."""

    model_config = ConfigDict(extra="forbid", strict=True)

    name: Name | None = None
    number: Number | None = None
    description: Description | None = None
    policy: Policy | None = None
    max_views: int | None = Field(None, ge=1, le=3)
    sort: bool | None = None
    threshold: Threshold = None
    belt_mode: BeltMode | None = None
    speed: Speed = None
    balance_light: bool | None = None
    models: Models | None = None
    bins: Bins | None = None
    reason: Reason = None


class ActivateIn(BaseModel):
    """Why the recipe is selected (optional)."""

    model_config = ConfigDict(extra="forbid", strict=True)

    reason: Reason = None


class RecipePublic(BaseModel):
    id: int
    name: str
    number: int
    description: str
    policy: str
    max_views: int
    sort: bool
    threshold: float | None
    belt_mode: str | None
    speed: float | None
    balance_light: bool
    models: list[str]
    bins: dict[str, str]
    active: bool = Field(description="Whether it is the cell's active recipe")
    created_at: datetime
    updated_at: datetime


class RecipeList(BaseModel):
    data: list[RecipePublic]
    count: int
    active: RecipePublic | None = Field(description="The cell's active recipe (null: none)")


_OPTIONS = ("policy", "max_views", "sort", "threshold", "belt_mode", "speed", "balance_light")
_NULLABLE = {"threshold", "belt_mode", "speed"}


def _by(user: Any, reason: str | None) -> audit.By:
    return audit.By(audit.Actor.of(user), reason)


@router.get(
    "", response_model=RecipeList, summary="The cell's recipes by number, and the active one"
)
async def read_recipes(
    _: ViewerUser,
    rt: RuntimeDep,
    limit: Annotated[int, Query(ge=1, le=1000)] = 100,
    offset: Annotated[int, Query(ge=0, le=2**31 - 1)] = 0,
) -> dict[str, Any]:
    rows = await svc.list_recipes(rt)
    active = next((r for r in rows if r.active), None)
    return {"data": [r.public() for r in rows[offset : offset + limit]], "count": len(rows),
            "active": None if active is None else active.public()}  # fmt: skip


@router.post("", response_model=RecipePublic, status_code=status.HTTP_201_CREATED,
             summary="Create a recipe (engineer)")  # fmt: skip
async def create_recipe(user: EngineerUser, rt: RuntimeDep, body: RecipeCreate) -> dict[str, Any]:
    fields = svc.RecipeFields(
        name=body.name, number=body.number, description=body.description,
        options={k: getattr(body, k) for k in _OPTIONS}, models=body.models, bins=body.bins,
    )  # fmt: skip
    return (await svc.create_recipe(rt, fields, by=_by(user, body.reason))).public()


class BinPublic(BaseModel):
    name: str
    parts: list[str] = Field(description="Parts sorted into it by default")
    reject: bool = Field(description="The bin of unknown and failed objects")


class BinList(BaseModel):
    data: list[BinPublic]
    count: int


@router.get("/bins", response_model=BinList,
            summary="The cell's sorting bins a recipe may name (none in a cell without bins)")  # fmt: skip
async def read_bins(_: ViewerUser, rt: RuntimeDep) -> dict[str, Any]:
    bins = rt.layout.bins
    data = [{"name": b.name, "parts": list(b.parts), "reject": bool(b.reject)} for b in bins]
    return {"data": data, "count": len(data)}


@router.get("/{recipe_id}", response_model=RecipePublic, summary="One recipe")
async def read_recipe(_: ViewerUser, rt: RuntimeDep, recipe_id: RecipeId) -> dict[str, Any]:
    return (await svc.get_recipe(rt, recipe_id)).public()


@router.patch("/{recipe_id}", response_model=RecipePublic, summary="Change a recipe (engineer)")
async def update_recipe(
    user: EngineerUser, rt: RuntimeDep, recipe_id: RecipeId, body: RecipeUpdate
) -> dict[str, Any]:
    given = body.model_fields_set - {"reason"}
    for key in given - _NULLABLE:
        if getattr(body, key) is None:
            raise InvalidInput(f"{key} may not be null (leave it out to keep it)")
    options = {k: getattr(body, k) for k in _OPTIONS if k in given}
    fields = svc.RecipeFields(
        name=body.name, number=body.number, description=body.description,
        options=options or None, models=body.models, bins=body.bins,
    )  # fmt: skip
    return (await svc.update_recipe(rt, recipe_id, fields, by=_by(user, body.reason))).public()


@router.delete("/{recipe_id}", status_code=status.HTTP_204_NO_CONTENT,
               summary="Delete a recipe (engineer; not the active one)")  # fmt: skip
async def delete_recipe(
    user: EngineerUser,
    rt: RuntimeDep,
    recipe_id: RecipeId,
    reason: Annotated[
        str | None, Query(max_length=audit.MAX_REASON_LENGTH, description="Why (audit trail)")
    ] = None,
) -> None:
    await svc.delete_recipe(rt, recipe_id, by=_by(user, reason))


@router.post("/{recipe_id}/activate", response_model=RecipePublic,
             summary="Make a recipe the cell's active one (operator: a line changeover); "
             "runs following it take it from their next object")  # fmt: skip
async def activate_recipe(
    user: OperatorUser, rt: RuntimeDep, recipe_id: RecipeId, body: ActivateIn | None = None
) -> dict[str, Any]:
    reason = None if body is None else body.reason
    return (await svc.activate(rt, recipe_id, actor=audit.Actor.of(user), reason=reason)).public()
