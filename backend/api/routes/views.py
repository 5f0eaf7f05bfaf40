"""A model's trained views: list, image, delete, upload (images with their viewpoints).

Reading needs the viewer role; deleting and uploading need the engineer role.  The work is
in :mod:`backend.recognition.views`; handlers only parse, call it and shape the answer.
"""

from __future__ import annotations

import json
import math
from typing import Annotated, Any

from fastapi import APIRouter, File, Form, Query, UploadFile, status
from fastapi.responses import Response

from backend import audit
from backend.api.deps import DatabaseDep, EngineerUser, SessionDep, ViewerUser
from backend.api.routes.modelforms import DB_ID_MAX, ModelId, ReasonQuery, ViewId, ViewList
from backend.api.routes.models import LiveIndexDep, _by
from backend.api.uploads import read_capped
from backend.api.work import HeavyWorkDep
from backend.recognition import images as im
from backend.recognition import views as views_svc
from backend.recognition.index import LiveIndex
from vision.errors import InvalidInput

__all__ = ["router"]

router = APIRouter(prefix="/models", tags=["models"])


def _view_out(row: Any, live: LiveIndex) -> dict[str, Any]:
    out = views_svc.view_public(row)
    out["indexed"] = live.has_view(row.id)
    stale = live.stale.get(row.id)
    out["stale"] = None if stale is None else stale.reason
    return out


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
    responses={
        200: {
            "content": {"image/png": {}, "image/jpeg": {}},
            "description": "The image or mask (PNG) or the thumbnail (JPEG)",
        }
    },
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
