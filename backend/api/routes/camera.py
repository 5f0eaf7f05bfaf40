"""The live camera image."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter
from fastapi.responses import Response
from pydantic import BaseModel

from backend.api.deps import CellDep, ViewerUser
from backend.api.errors import ApiError
from backend.api.fastpath import FastRequest, Fresh

router = APIRouter(prefix="/camera", tags=["camera"])


class CameraStatusOut(BaseModel):
    name: str
    ok: bool
    frames: int
    fps: float
    error: str


def frame_response(jpeg: bytes) -> Response:
    """The answer of one JPEG frame."""
    return Response(jpeg, media_type="image/jpeg", headers={"Cache-Control": "no-store"})


@router.get(
    "/frame.jpg",
    summary="The latest camera frame as JPEG",
    response_class=Response,
    responses={200: {"content": {"image/jpeg": {}}, "description": "The frame"}},
)
async def read_frame(_: ViewerUser, cell: CellDep) -> Response:
    jpeg = await cell.latest_jpeg_async()  # a new frame's JPEG encoded off the event loop
    if jpeg is None:
        status = cell.camera_status()
        raise ApiError(503, "camera_unavailable", status.error or "no frame has arrived yet")
    return frame_response(jpeg)


async def fast_read_frame(req: FastRequest) -> Fresh | None:
    """:func:`read_frame` when there is a frame (else FastAPI answers the 503); kept per
    frame."""
    jpeg = await req.runtime.cell.latest_jpeg_async()
    if jpeg is None:
        return None
    return Fresh((jpeg,), lambda: frame_response(jpeg))


def camera_status_answer(cell: Any) -> dict[str, Any]:
    """The camera's status answer now."""
    result: dict[str, Any] = cell.camera_status().as_dict()
    return result


@router.get("/status", summary="Camera health and rate", response_model=CameraStatusOut)
async def read_camera_status(_: ViewerUser, cell: CellDep) -> dict[str, Any]:
    return camera_status_answer(cell)


async def fast_read_camera_status(req: FastRequest) -> Fresh | None:
    """:func:`read_camera_status` (kept while the status is equal)."""
    return Fresh.of_content(camera_status_answer(req.runtime.cell))
