"""Inspections: one object (a job), continuous operation (start, stop), the stored results.

Reading needs the viewer role; inspecting, running and stopping need the operator role.
The work is in :mod:`backend.inspection`; handlers only parse, call it and shape the answer.
"""

from __future__ import annotations

from collections.abc import Hashable, Mapping
from datetime import datetime
from typing import TYPE_CHECKING, Annotated, Any, Literal

from fastapi import APIRouter, Path, Query, status
from fastapi.responses import Response
from pydantic import BaseModel, ConfigDict, Field
from sqlalchemy.ext.asyncio import AsyncSession

from backend.api.deps import (
    DatabaseDep,
    EngineerUser,
    OperatorUser,
    ReadCacheDep,
    RuntimeDep,
    SessionDep,
    ViewerUser,
    read_through,
)
from backend.api.fastpath import FastRequest, Fresh
from backend.api.schemas import JobOut, Page
from backend.api.types import DbId, Limit, Offset, instant_query
from backend.inspection import results, service
from backend.inspection.public import InspectionPublic
from backend.recipes import follower, resolve_options

__all__ = ["router"]

router = APIRouter(tags=["inspections"])

if TYPE_CHECKING:  # the value a handler receives; FastAPI reads the Annotated form
    Since = datetime | None
    Until = datetime | None
else:
    Since = instant_query("Started at or after this time")
    Until = instant_query("Started at or before this time")

Policy = Literal["naive", "top-only", "two-views", "best-next"]


class InspectIn(BaseModel):
    """Options of one inspection (see ``backend.inspection.options.InspectOptions``): the
    active recipe's (or ``recipe``'s), with the options given here over them; without a
    recipe, the defaults below."""

    model_config = ConfigDict(extra="forbid", strict=True)

    policy: Policy = "two-views"
    sort: bool = Field(False, description="Pick and sort into the part's bin")
    max_views: int = Field(3, ge=1, le=3)
    wait_s: float = Field(
        60.0, ge=0.0, le=service.MAX_WAIT_S, allow_inf_nan=False,
        description="One inspection: longest wait for a part, s (then its job fails no_object "
        "and nothing is stored); a run waits until a part comes or it is stopped",
    )  # fmt: skip
    speed: float | None = Field(None, gt=0.0, le=1.0, allow_inf_nan=False)
    balance_light: bool = Field(
        True, description="Scale the views back to the teach light by the belt's colour"
    )
    recipe: int | None = Field(
        None, ge=1, le=2**31 - 1, description="Recipe id to use instead of the active one"
    )

    def overrides(self) -> dict[str, Any]:
        """The options given explicitly (they override the recipe's)."""
        return {k: getattr(self, k) for k in self.model_fields_set - {"recipe", "count"}}


class RunIn(InspectIn):
    """Continuous operation: inspect objects until stopped, or ``count`` of them."""

    count: int | None = Field(None, ge=1, le=service.MAX_COUNT)


@router.post(
    "/inspections",
    response_model=JobOut,
    status_code=status.HTTP_202_ACCEPTED,
    summary="Inspect the object at the station: a job whose result names the inspection "
    "(operator); the active recipe's options unless the request names others",
)
async def create_inspection(_: OperatorUser, rt: RuntimeDep, body: InspectIn) -> dict[str, Any]:
    opts = await resolve_options(rt, body.overrides(), recipe_id=body.recipe)
    job = await service.start_inspection(rt, opts)
    return {"job": job.public()}


@router.post(
    "/inspection/run",
    response_model=JobOut,
    status_code=status.HTTP_202_ACCEPTED,
    summary="Start continuous inspection (operator): it follows the active recipe (or "
    "`recipe`), read again before each object, under the options given",
)
async def start_run(_: OperatorUser, rt: RuntimeDep, body: RunIn) -> dict[str, Any]:
    overrides = body.overrides()
    opts = await resolve_options(rt, overrides, recipe_id=body.recipe)
    resolve = follower(rt, overrides, recipe_id=body.recipe)
    run = service.start_run(rt, opts, body.count, resolve=resolve)
    return {"job": run.job.public()}


@router.post(
    "/inspection/belt-background",
    response_model=JobOut,
    status_code=status.HTTP_202_ACCEPTED,
    summary="Grab the empty belt's background registered to its travel (engineer; belt and "
    "station empty): needed at constant belt speed",
)
async def grab_belt_background(_: EngineerUser, rt: RuntimeDep) -> dict[str, Any]:
    job = service.start_belt_background(rt)
    return {"job": job.public()}


@router.post(
    "/inspection/stop",
    response_model=JobOut,
    status_code=status.HTTP_202_ACCEPTED,
    summary="End continuous inspection after the current object (operator)",
)
async def stop_run(_: OperatorUser, rt: RuntimeDep) -> dict[str, Any]:
    run = service.stop_run(rt)
    return {"job": run.job.public()}


#: What the inspection list reads (its read-cache entries go when one of them is written).
INSPECTION_TABLES = ("inspections", "inspection_images")


def inspections_key(cell_id: int | None, params: Mapping[str, Any]) -> tuple[Hashable, ...]:
    """The read-cache key of one page of this cell's inspection list; ``params`` by the
    query parameters' names."""
    return ("inspections", cell_id, *(params[name] for name in _LIST_PARAMS))


_LIST_PARAMS = ("limit", "offset", "decision", "model", "policy", "since", "until")


@router.get(
    "/inspections",
    summary="Stored inspections of this cell, newest first",
    response_model=Page[InspectionPublic],
)
async def read_inspections(
    user: ViewerUser,
    rt: RuntimeDep,
    db: DatabaseDep,
    cache: ReadCacheDep,
    limit: Limit = 50,
    offset: Offset = 0,
    decision: Literal["recognized", "unknown", "failed"] | None = None,
    model: Annotated[str | None, Query(min_length=1, max_length=64)] = None,
    policy: Policy | None = None,
    since: Since = None,
    until: Until = None,
) -> Page[InspectionPublic]:
    async def read(session: AsyncSession) -> Page[InspectionPublic]:
        data, total = await results.list_inspections(
            session, cell_id=rt.cell_id, limit=limit, offset=offset, decision=decision,
            model=model, policy=policy, since=since, until=until,
        )  # fmt: skip
        return Page[InspectionPublic](
            data=[InspectionPublic.model_validate(d) for d in data], count=total
        )

    params = {"limit": limit, "offset": offset, "decision": decision, "model": model,
              "policy": policy, "since": since, "until": until}  # fmt: skip
    key = inspections_key(rt.cell_id, params)
    return await read_through(cache, db, user, key, tables=INSPECTION_TABLES, read=read)


async def fast_read_inspections(req: FastRequest) -> Fresh | None:
    """:func:`read_inspections` from its read-cache answer, if it has a fresh one for the
    role."""
    if req.role is None:
        return None
    key = inspections_key(req.runtime.cell_id, req.params)
    entry = req.runtime.read_cache.peek(key, role=req.role, topics=INSPECTION_TABLES)
    if entry is None:
        return None
    value: Page[InspectionPublic] = entry.value
    return Fresh((entry,), lambda: value)


@router.get(
    "/inspections/{inspection_id}", summary="One inspection", response_model=InspectionPublic
)
async def read_inspection(
    _: ViewerUser, rt: RuntimeDep, session: SessionDep, inspection_id: DbId
) -> InspectionPublic:
    row = await results.get_inspection(session, inspection_id, rt.cell_id)
    return InspectionPublic.model_validate(results.inspection_public(row))


@router.get(
    "/inspections/{inspection_id}/images/{n}.jpg",
    response_class=Response,
    summary="The n-th viewpoint image (0-based) with the contour drawn",
    responses={200: {"content": {"image/jpeg": {}}, "description": "The image (JPEG)"}},
)
async def read_inspection_image(
    _: ViewerUser,
    rt: RuntimeDep,
    session: SessionDep,
    inspection_id: DbId,
    n: Annotated[int, Path(ge=0, le=9)],
) -> Response:
    data = await results.get_image(session, inspection_id, n, rt.cell_id)
    return Response(data, media_type="image/jpeg")
