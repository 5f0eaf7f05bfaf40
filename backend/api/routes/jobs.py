"""Jobs: list, read, cancel."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter

from backend.api.deps import CellDep, OperatorUser, ViewerUser
from backend.api.errors import ApiError

router = APIRouter(prefix="/jobs", tags=["jobs"])


@router.get("", summary="Recent jobs, newest first")
async def read_jobs(_: ViewerUser, cell: CellDep) -> dict[str, Any]:
    data = [j.public() for j in cell.jobs.list()]
    return {"data": data, "count": len(data)}


def _job(cell: Any, job_id: str) -> Any:
    job = cell.jobs.get(job_id)
    if job is None:
        raise ApiError(404, "not_found", f"no job with id {job_id!r}")
    return job


@router.get("/{job_id}", summary="One job")
async def read_job(_: ViewerUser, cell: CellDep, job_id: str) -> dict[str, Any]:
    return {"job": _job(cell, job_id).public()}


@router.post("/{job_id}/cancel", summary="Cancel a running job")
async def cancel_job(_: OperatorUser, cell: CellDep, job_id: str) -> dict[str, Any]:
    job = _job(cell, job_id)
    if job.motion:
        await cell.stop_motion()
    await cell.jobs.cancel(job)
    return {"job": job.public()}
