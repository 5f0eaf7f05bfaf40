"""The negative images the automatic threshold is chosen against (under
``/api/recognition``): list, upload, delete.

Reading needs the viewer role; changing the negatives the engineer role.  The work is in
:mod:`backend.recognition.negatives`; every change tells the threshold keeper.
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, File, Form, Path, Query, UploadFile, status
from fastapi.responses import Response
from pydantic import BaseModel

from backend import audit
from backend.api.deps import DatabaseDep, EngineerUser, RuntimeDep, ViewerUser
from backend.api.routes.recognition import DB_ID_MAX
from backend.api.uploads import read_capped
from backend.api.work import HeavyWorkDep
from backend.recognition import images as im
from backend.recognition import negatives as neg
from backend.recognition import public
from backend.runtime import CellRuntime
from vision.errors import InvalidInput

__all__ = ["router"]

router = APIRouter(prefix="/recognition", tags=["recognition"])


# -- negative images ------------------------------------------------------------------------


class NegativeList(BaseModel):
    data: list[public.NegativePublic]
    count: int


def _keeper_changed(runtime: CellRuntime) -> None:
    keeper = runtime.threshold_keeper
    if keeper is not None:
        keeper.changed()


@router.get("/negatives", response_model=NegativeList, summary="Negative images (no image data)")
async def read_negatives(
    _: ViewerUser,
    db: DatabaseDep,
    limit: Annotated[int, Query(ge=1, le=500)] = 100,
    offset: Annotated[int, Query(ge=0, le=DB_ID_MAX)] = 0,
) -> dict[str, Any]:
    rows, total = await neg.list_negatives(db, limit=limit, offset=offset)
    return {"data": [public.NegativePublic.model_validate(r) for r in rows], "count": total}


@router.post(
    "/negatives",
    response_model=NegativeList,
    status_code=status.HTTP_201_CREATED,
    summary="Upload negative images: the empty belt, other things in the scene (engineer)",
)
async def create_negatives(
    user: EngineerUser,
    runtime: RuntimeDep,
    work: HeavyWorkDep,
    images: Annotated[list[UploadFile], File(description="PNG or JPEG images of no model")],
    note: Annotated[str, Form(max_length=200, description="What they show")] = "",
    reason: Annotated[
        str | None, Form(max_length=audit.MAX_REASON_LENGTH, description="Why (audit trail)")
    ] = None,
) -> dict[str, Any]:
    n = len(images)
    if n > neg.MAX_NEGATIVES_PER_REQUEST:
        raise InvalidInput(f"at most {neg.MAX_NEGATIVES_PER_REQUEST} images at once, got {n}")
    names = [f.filename or f"image {k}" for k, f in enumerate(images)]
    datas = [await read_capped(f, im.MAX_IMAGE_BYTES) for f in images]
    heads = [im.check_header(d, name=nm) for d, nm in zip(datas, names, strict=True)]

    def decode_all() -> list[tuple[bytes, int, int]]:
        rgbs = [im.decode_image(d, name=nm) for d, nm in zip(datas, names, strict=True)]
        return neg.encode_negatives(rgbs)

    async with work.job() as job:
        for h, nm in zip(heads, names, strict=True):
            job.take_pixels(h.width, h.height, name=nm, analysed=True)
        encoded = await job.run(decode_all)
    rows = await neg.add_negatives(
        runtime.database, encoded, note=note, by=audit.By(audit.Actor.of(user), reason)
    )
    _keeper_changed(runtime)
    return {"data": [public.NegativePublic.model_validate(r) for r in rows], "count": len(rows)}


@router.delete(
    "/negatives/{negative_id}",
    status_code=status.HTTP_204_NO_CONTENT,
    summary="Delete a negative image (engineer)",
)
async def delete_negative(
    user: EngineerUser,
    runtime: RuntimeDep,
    negative_id: Annotated[int, Path(ge=1, le=DB_ID_MAX, description="Negative image id")],
    reason: Annotated[
        str | None, Query(max_length=audit.MAX_REASON_LENGTH, description="Why (audit trail)")
    ] = None,
) -> Response:
    await neg.delete_negative(
        runtime.database, negative_id, by=audit.By(audit.Actor.of(user), reason)
    )
    _keeper_changed(runtime)
    return Response(status_code=status.HTTP_204_NO_CONTENT)
