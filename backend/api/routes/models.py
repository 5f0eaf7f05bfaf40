"""Object models; teaching (a job).  Their trained views: :mod:`backend.api.routes.views`.

Reading needs the viewer role; creating, changing, deleting and teaching need the engineer
role.  The work is in :mod:`backend.recognition`; handlers only parse, call
it and shape the answer.
"""

from __future__ import annotations

from collections.abc import Hashable
from typing import Annotated, Any

import numpy as np
from fastapi import APIRouter, Depends, Query, status
from fastapi.responses import Response
from sqlalchemy.ext.asyncio import AsyncSession

from backend import audit
from backend.api.deps import (
    CellDep,
    DatabaseDep,
    EngineerUser,
    ReadCacheDep,
    RuntimeDep,
    SessionDep,
    ViewerUser,
    read_through,
)
from backend.api.fastpath import FastRequest, Fresh
from backend.api.routes.modelforms import (
    DB_ID_MAX,
    ModelCreate,
    ModelId,
    ModelList,
    ModelPublic,
    ModelUpdate,
    ReasonQuery,
    TeachIn,
    _height_fields,
)
from backend.api.schemas import JobOut
from backend.recognition import models as svc
from backend.recognition import teach as teach_svc
from backend.recognition.index import IndexedModel, LiveIndex
from vision.errors import InvalidInput

__all__ = ["LiveIndexDep", "get_live_index", "router"]

router = APIRouter(prefix="/models", tags=["models"])


def _by(user: Any, reason: str | None) -> audit.By:
    return audit.By(audit.Actor.of(user), reason)


async def get_live_index(runtime: RuntimeDep) -> LiveIndex:
    """The live index of the running cell (built from the database at start-up)."""
    return runtime.live_index


LiveIndexDep = Annotated[LiveIndex, Depends(get_live_index)]


def _model_out(
    row: Any, counts: dict[int, int], live: LiveIndex, rounds: int = 0
) -> dict[str, Any]:
    return _live_out(svc.model_public(row, counts, rounds), live)


async def _counted_out(session: AsyncSession, row: Any, live: LiveIndex) -> dict[str, Any]:
    """A model's public form with its view counts and teach rounds read now."""
    counts = await svc.view_counts(session, [row.id])
    rounds = await svc.taught_rounds(session, [row.id])
    return _model_out(row, counts[row.id], live, rounds[row.id])


def _live_out(public: dict[str, Any], live: LiveIndex) -> dict[str, Any]:
    """A copy of a model's public dict with the live index's counts of its views."""
    mid = public["id"]
    return {
        **public,
        "indexed_views": len(live.views_of(mid)),
        "stale_views": sum(1 for s in live.stale.values() if s.model_id == mid),
    }


# -- models ---------------------------------------------------------------------------------


#: What the model list reads (its read-cache entries go when one of them is written).
MODEL_TABLES = ("object_models", "trained_views")


def models_key(limit: int, offset: int, part: str | None) -> tuple[Hashable, ...]:
    """The read-cache key of one page of the model list."""
    return ("models", limit, offset, part)


def models_answer(value: tuple[list[dict[str, Any]], int], live: LiveIndex) -> dict[str, Any]:
    """The list's answer from its read (rows and view counts, total) and the live index."""
    data, total = value
    return {"data": [_live_out(d, live) for d in data], "count": total}


@router.get("", response_model=ModelList, summary="Object models, by name")
async def read_models(
    user: ViewerUser,
    db: DatabaseDep,
    cache: ReadCacheDep,
    live: LiveIndexDep,
    limit: Annotated[int, Query(ge=1, le=1000)] = 100,
    offset: Annotated[int, Query(ge=0, le=DB_ID_MAX)] = 0,
    part: Annotated[str | None, Query(max_length=64)] = None,
) -> dict[str, Any]:
    async def read(session: AsyncSession) -> tuple[list[dict[str, Any]], int]:
        rows, total = await svc.list_models(session, limit=limit, offset=offset, part=part)
        counts = await svc.view_counts(session, [r.id for r in rows])
        rounds = await svc.taught_rounds(session, [r.id for r in rows])
        return [svc.model_public(r, counts[r.id], rounds[r.id]) for r in rows], total

    # The rows and view counts from the database, cached; the live index's part (in
    # memory, changed without a commit) per request.
    value = await read_through(
        cache, db, user, models_key(limit, offset, part), tables=MODEL_TABLES, read=read
    )
    return models_answer(value, live)


async def fast_read_models(req: FastRequest) -> Fresh | None:
    """:func:`read_models` from its read-cache entry, if it has a fresh one for the role;
    its answer is kept while the live index has not changed (its generation)."""
    if req.role is None:
        return None
    p = req.params
    key = models_key(p["limit"], p["offset"], p["part"])
    entry = req.runtime.read_cache.peek(key, role=req.role, topics=MODEL_TABLES)
    if entry is None:
        return None
    live = req.runtime.live_index
    generation = live.generation
    return Fresh(
        (entry, generation),
        lambda: models_answer(entry.value, live),
        still=lambda: live.generation == generation,
    )


@router.post(
    "",
    response_model=ModelPublic,
    status_code=status.HTTP_201_CREATED,
    summary="Create an object model (engineer)",
)
async def create_model(
    user: EngineerUser, db: DatabaseDep, live: LiveIndexDep, body: ModelCreate
) -> dict[str, Any]:
    data = body.model_dump(exclude={"reason", "height_m", "height_mm"})
    given = set(body.model_fields_set)
    height = _height_fields(body, given)
    fields = svc.ModelFields(
        **data, **height, height_given=bool(height), grasp_given="grasp_obj" in given
    )
    row = await svc.create_model(db, fields, by=_by(user, body.reason))
    live.put_model(IndexedModel.of(row))
    return _model_out(row, {}, live)


@router.get("/{model_id}", response_model=ModelPublic, summary="One object model")
async def read_model(
    _: ViewerUser, session: SessionDep, live: LiveIndexDep, model_id: ModelId
) -> dict[str, Any]:
    row = await svc.get_model(session, model_id)
    return await _counted_out(session, row, live)


@router.patch("/{model_id}", response_model=ModelPublic, summary="Change a model (engineer)")
async def update_model(
    user: EngineerUser,
    db: DatabaseDep,
    session: SessionDep,
    live: LiveIndexDep,
    model_id: ModelId,
    body: ModelUpdate,
) -> dict[str, Any]:
    given = body.model_fields_set - {"reason"}
    for key in ("name", "part", "sitting_base", "kind", "description"):
        if key in given and getattr(body, key) is None:
            raise InvalidInput(f"{key} may not be null (leave it out to keep it)")
    height = _height_fields(body, given)
    fields = svc.ModelFields(
        **{k: getattr(body, k) for k in given - {"height_m", "height_mm"}},
        **height,
        threshold_given="threshold" in given,
        height_given=bool(height),
        grasp_given="grasp_obj" in given,
    )
    _before, row = await svc.update_model(db, model_id, fields, by=_by(user, body.reason))
    live.put_model(IndexedModel.of(row))
    return await _counted_out(session, row, live)


@router.delete(
    "/{model_id}",
    status_code=status.HTTP_204_NO_CONTENT,
    summary="Delete a model and its trained views (engineer)",
)
async def delete_model(
    user: EngineerUser,
    db: DatabaseDep,
    live: LiveIndexDep,
    model_id: ModelId,
    reason: ReasonQuery = None,
) -> Response:
    await svc.delete_model(db, model_id, by=_by(user, reason))
    live.drop_model(model_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)


# -- teaching -------------------------------------------------------------------------------


def get_backgrounds(runtime: RuntimeDep) -> teach_svc.BackgroundStore:
    """The backgrounds grabbed by earlier teaches of this cell."""
    return runtime.teach_backgrounds


@router.post(
    "/{model_id}/teach",
    response_model=JobOut,
    status_code=status.HTTP_202_ACCEPTED,
    summary="Teach the model with the arm: a job (engineer)",
)
async def teach_model(
    user: EngineerUser,
    db: DatabaseDep,
    live: LiveIndexDep,
    cell: CellDep,
    rt: RuntimeDep,
    model_id: ModelId,
    body: TeachIn,
    store: Annotated[teach_svc.BackgroundStore, Depends(get_backgrounds)],
) -> dict[str, Any]:
    options = teach_svc.TeachOptions(
        viewpoints=None if body.viewpoints is None else tuple(body.viewpoints),
        top_rolls_rad=teach_svc.TOP_ROLLS_RAD
        if body.top_rolls_rad is None
        else tuple(body.top_rolls_rad),
        background=body.background,
        object_height_m=body.object_height_m,
        yaw_rad=body.yaw_rad,
        speed=body.speed,
        wait_s=body.wait_s,
        replace=body.replace,
        threshold=body.threshold,
    )
    job = await teach_svc.start_teach(
        cell=cell,
        db=db,
        live=live,
        model_id=model_id,
        options=options,
        store=store,
        point=rt.layout.station_point
        if body.point is None
        else np.asarray(body.point, dtype=np.float64),
        by=_by(user, body.reason),
        heavy=rt.heavy,
        # Without a calibration: the camera's exact nominal lens and mounting (the
        # simulator's), as inspections use them.
        camera=None if rt.nominal_camera is None else rt.nominal_camera.camera,
        mounting=None if rt.nominal_camera is None else rt.nominal_camera.T_ee_cam,
        keeper=rt.threshold_keeper,
    )
    return {"job": job.public()}
