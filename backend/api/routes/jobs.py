"""Jobs: list, read, cancel."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Depends, Path

from backend.api.deps import CellDep, OperatorUser, ViewerUser
from backend.api.fastpath import FastRequest, Fresh
from backend.api.schemas import JobOut, JobPublic, Page, page
from backend.api.types import Limit, Offset
from backend.jobs import Job
from vision.errors import NotFound

router = APIRouter(prefix="/jobs", tags=["jobs"])

JobId = Annotated[
    str, Path(min_length=1, max_length=64, description="Job id from the answer that started it")
]


async def get_job(cell: CellDep, job_id: JobId) -> Job:
    """The job with this id; :class:`NotFound` if it is unknown or forgotten."""
    job = cell.jobs.get(job_id)
    if job is None:
        raise NotFound(f"no job with id {job_id!r}")
    return job


JobDep = Annotated[Job, Depends(get_job)]


def jobs_answer(cell: Any, limit: int, offset: int) -> dict[str, Any]:
    """One page of the recent jobs, newest first (only that page's jobs made public)."""
    jobs = cell.jobs.list()
    return {"data": [j.public() for j in page(jobs, limit=limit, offset=offset)["data"]],
            "count": len(jobs)}  # fmt: skip


@router.get("", summary="Recent jobs, newest first", response_model=Page[JobPublic])
async def read_jobs(
    _: ViewerUser, cell: CellDep, limit: Limit = 100, offset: Offset = 0
) -> dict[str, Any]:
    return jobs_answer(cell, limit, offset)


async def fast_read_jobs(req: FastRequest) -> Fresh | None:
    """:func:`read_jobs` (kept while the page is equal)."""
    return Fresh.of_content(
        jobs_answer(req.runtime.cell, req.params["limit"], req.params["offset"])
    )


@router.get("/{job_id}", summary="One job", response_model=JobOut)
async def read_job(_: ViewerUser, job: JobDep) -> dict[str, Any]:
    return {"job": job.public()}


@router.post("/{job_id}/cancel", summary="Cancel a running job", response_model=JobOut)
async def cancel_job(_: OperatorUser, cell: CellDep, job: JobDep) -> dict[str, Any]:
    if job.motion:
        await cell.stop_motion()
    await cell.jobs.cancel(job)
    return {"job": job.public()}
