"""Object models and their trained views; teaching (a job).

Reading needs the viewer role; creating, changing, deleting, uploading and teaching need
the engineer role.  The work is in :mod:`backend.recognition`; handlers only parse, call
it and shape the answer.
"""

from __future__ import annotations

import json
import math
from collections.abc import Hashable
from datetime import datetime
from typing import Annotated, Any, Literal

import numpy as np
from fastapi import APIRouter, Depends, File, Form, Path, Query, UploadFile, status
from fastapi.responses import Response
from pydantic import BaseModel, ConfigDict, Field
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
from backend.api.uploads import read_capped
from backend.api.work import HeavyWorkDep
from backend.recognition import images as im
from backend.recognition import models as svc
from backend.recognition import teach as teach_svc
from backend.recognition import views as views_svc
from backend.recognition.index import IndexedModel, LiveIndex
from vision.errors import InvalidInput

__all__ = ["LiveIndexDep", "get_live_index", "router"]

router = APIRouter(prefix="/models", tags=["models"])

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


def _by(user: Any, reason: str | None) -> audit.By:
    return audit.By(audit.Actor.of(user), reason)


async def get_live_index(runtime: RuntimeDep) -> LiveIndex:
    """The live index of the running cell (built from the database at start-up)."""
    return runtime.live_index


LiveIndexDep = Annotated[LiveIndex, Depends(get_live_index)]


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


class TeachRounds(BaseModel):
    taught: int = Field(description="Teach rounds: distinct object yaws of the top views")
    recommended: int = Field(
        description="Rounds a model of this kind needs to be recognised at any yaw"
    )


class ModelPublic(BaseModel):
    id: int
    name: str
    part: str
    sitting_base: str
    kind: str
    threshold: float | None
    description: str
    height_m: float | None = Field(description="Height above the sitting base, metres")
    grasp_obj: list[float] | None = Field(description="Suction point, object frame, metres")
    geometry_source: str = Field(description="measured (teach), entered (engineer) or empty")
    created_at: datetime
    views: int
    views_per_viewpoint: dict[str, int]
    rounds: TeachRounds
    indexed_views: int = Field(description="Views in the live index")
    stale_views: int = Field(description="Views refused by the index (stale features)")


class ModelList(BaseModel):
    data: list[ModelPublic]
    count: int


class ViewPublic(BaseModel):
    id: int
    model_id: int
    viewpoint: int
    width: int
    height: int
    keypoints: int
    descriptor: dict[str, str]
    yaw_rad: float
    roll_rad: float
    source: str
    joints: list[float] | None
    T_base_cam: list[list[float]] | None
    created_at: datetime
    image_url: str
    thumbnail_url: str
    mask_url: str
    indexed: bool
    stale: str | None = Field(description="Why the index refused the view, if it did")


class ViewList(BaseModel):
    data: list[ViewPublic]
    count: int


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


def _view_out(row: Any, live: LiveIndex) -> dict[str, Any]:
    out = views_svc.view_public(row)
    out["indexed"] = live.has_view(row.id)
    stale = live.stale.get(row.id)
    out["stale"] = None if stale is None else stale.reason
    return out


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


class JobAccepted(BaseModel):
    job: dict[str, Any]


def get_backgrounds(runtime: RuntimeDep) -> teach_svc.BackgroundStore:
    """The backgrounds grabbed by earlier teaches of this cell."""
    return runtime.teach_backgrounds


@router.post(
    "/{model_id}/teach",
    response_model=JobAccepted,
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


# -- views ----------------------------------------------------------------------------------


@router.get("/{model_id}/views", response_model=ViewList, summary="A model's trained views")
async def read_views(
    _: ViewerUser,
    session: SessionDep,
    live: LiveIndexDep,
    model_id: ModelId,
    viewpoint: Annotated[int | None, Query(ge=1, le=3)] = None,
    limit: Annotated[int, Query(ge=1, le=500)] = 100,
    offset: Annotated[int, Query(ge=0, le=DB_ID_MAX)] = 0,
) -> dict[str, Any]:
    rows, total = await views_svc.list_views(
        session, model_id, viewpoint=viewpoint, limit=limit, offset=offset
    )
    return {"data": [_view_out(r, live) for r in rows], "count": total}


@router.get(
    "/{model_id}/views/{view_id}/image",
    summary="A view's image (PNG), thumbnail (JPEG, ?thumb=1) or mask (PNG, ?mask=1)",
    responses={200: {"content": {"image/png": {}, "image/jpeg": {}}}},
    response_class=Response,
)
async def read_view_image(
    _: ViewerUser,
    session: SessionDep,
    model_id: ModelId,
    view_id: ViewId,
    thumb: Annotated[bool, Query()] = False,
    mask: Annotated[bool, Query()] = False,
) -> Response:
    if thumb and mask:
        raise InvalidInput("ask for thumb or mask, not both")
    part = "thumb" if thumb else "mask" if mask else "image"
    data, media = await views_svc.view_image(session, model_id, view_id, part=part)
    return Response(data, media_type=media, headers={"Cache-Control": "private, max-age=3600"})


@router.delete(
    "/{model_id}/views/{view_id}",
    status_code=status.HTTP_204_NO_CONTENT,
    summary="Delete a trained view (engineer)",
)
async def delete_view(
    user: EngineerUser,
    db: DatabaseDep,
    live: LiveIndexDep,
    model_id: ModelId,
    view_id: ViewId,
    reason: ReasonQuery = None,
) -> Response:
    await views_svc.delete_view(db, live, model_id, view_id, by=_by(user, reason))
    return Response(status_code=status.HTTP_204_NO_CONTENT)


def _number_list(text: str | None, n: int, what: str, *, lo: float, hi: float) -> list[float]:
    """A form field holding one number for every image, or a JSON list of ``n`` numbers."""
    if text is None or text.strip() == "":
        return []
    try:
        value = json.loads(text)
    except json.JSONDecodeError:
        raise InvalidInput(
            f"{what} must be a number or a JSON list of numbers, got {text[:80]!r}"
        ) from None
    values = value if isinstance(value, list) else [value] * n
    if len(values) != n:
        raise InvalidInput(f"{what} must list one value per image ({n}), got {len(values)}")
    out = []
    for k, v in enumerate(values):
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            raise InvalidInput(f"{what}[{k}] must be a finite number, got {v!r}")
        if not lo <= v <= hi:
            raise InvalidInput(f"{what}[{k}] must be within [{lo}, {hi}], got {v!r}")
        out.append(v)
    return out


@router.post(
    "/{model_id}/views",
    response_model=ViewList,
    status_code=status.HTTP_201_CREATED,
    summary="Upload trained views: images with their viewpoint, optional masks (engineer)",
)
async def create_views(
    user: EngineerUser,
    db: DatabaseDep,
    live: LiveIndexDep,
    work: HeavyWorkDep,
    model_id: ModelId,
    images: Annotated[list[UploadFile], File(description="PNG or JPEG images")],
    viewpoints: Annotated[
        str, Form(description="1, 2 or 3 for every image, or a JSON list, one per image")
    ] = "1",
    masks: Annotated[
        list[UploadFile] | None, File(description="Optional masks, one per image (white = object)")
    ] = None,
    yaws: Annotated[
        str | None, Form(description="Object yaw per image, radians (number or JSON list)")
    ] = None,
    reason: Annotated[
        str | None, Form(max_length=audit.MAX_REASON_LENGTH, description="Why (audit trail)")
    ] = None,
) -> dict[str, Any]:
    n = len(images)
    if n > views_svc.MAX_VIEWS_PER_REQUEST:
        raise InvalidInput(f"at most {views_svc.MAX_VIEWS_PER_REQUEST} images at once, got {n}")
    vps = _number_list(viewpoints, n, "viewpoints", lo=1, hi=3)
    if any(v != int(v) for v in vps):
        raise InvalidInput(f"viewpoints must be 1, 2 or 3, got {viewpoints!r}")
    yaw = _number_list(yaws, n, "yaws", lo=-2 * math.pi, hi=2 * math.pi) or [0.0] * n
    masks = masks or []
    if masks and len(masks) != n:
        raise InvalidInput(f"give one mask per image ({n}) or none, got {len(masks)}")
    # Decoding and feature extraction run in the heavy-work pool, within the request's
    # pixel budget (each file's size read from its header first); a client that leaves
    # drops what is still queued, and nothing is stored.
    async with work.job() as job:
        inputs = []
        for k, f in enumerate(images):
            name = f.filename or f"image {k}"
            data = await read_capped(f, im.MAX_IMAGE_BYTES)
            head = im.check_header(data, name=name)
            job.take_pixels(head.width, head.height, name=name, analysed=True)
            rgb = await job.run(im.decode_image, data, name=name)
            mask = None
            if masks:
                mname = masks[k].filename or f"mask {k}"
                mdata = await read_capped(masks[k], im.MAX_IMAGE_BYTES)
                mhead = im.check_header(mdata, name=mname)
                job.take_pixels(mhead.width, mhead.height, name=mname)
                mask = await job.run(im.decode_mask, mdata, shape=rgb.shape[:2], name=mname)
            inputs.append(
                views_svc.ViewInput(
                    rgb, int(vps[k]), mask, yaw_rad=float(yaw[k]), source="upload", name=name
                )
            )
        rows = await views_svc.add_views(
            db, live, model_id, inputs, by=_by(user, reason), run=job.run
        )
    return {"data": [_view_out(r, live) for r in rows], "count": len(rows)}
