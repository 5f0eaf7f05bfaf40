"""Calibration: solving a session as a job (under ``/api/calibration``), with its options.

Solving needs the engineer role.  The work itself is in :mod:`backend.calibration`.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import APIRouter, Query, status
from fastapi.responses import JSONResponse
from pydantic import BaseModel, Field, model_validator

from backend import calibration as svc
from backend.api.deps import CellDep, DatabaseDep, EngineerUser, SessionDep
from backend.api.errors import error_body
from backend.api.schemas import ErrorOut, JobOut, JobPublic
from backend.api.types import MAX_DB_ID, DbId, StrictBool, bounded_int
from backend.jobs import Job, JobState
from vision.calibration import ALL_METHODS, HandEyeOptions, IntrinsicsOptions

__all__ = ["router"]

router = APIRouter(prefix="/calibration", tags=["calibration"])


class SolveIn(BaseModel):
    """Options of a solve (see ``IntrinsicsOptions`` and ``HandEyeOptions``)."""

    radial_only: StrictBool = Field(False, description="Hold p1 = p2 = 0 (chapter: radial only)")
    k3: StrictBool = Field(False, description="Also estimate k3")
    fix_aspect_ratio: StrictBool = Field(False, description="fx = fy")
    reject_outliers: StrictBool = True
    min_views: Annotated[int, bounded_int(3, 1000, "Fewest accepted views to solve")] = 4
    methods: list[str] = Field(
        list(ALL_METHODS),
        max_length=len(ALL_METHODS),
        description=f"Hand-eye solvers, of {ALL_METHODS}",
    )
    refine: StrictBool = Field(True, description="Hand-eye: refine by reprojection error")
    loss: Literal["linear", "huber", "soft_l1", "cauchy"] = "linear"
    intrinsics: (
        Literal["session", "active"]
        | Annotated[int, bounded_int(1, MAX_DB_ID, "Id of an intrinsic calibration")]
    ) = Field(
        "session",
        description="Hand-eye: intrinsics from this session's images, the active ones, or a calibration id",
    )
    activate: StrictBool = Field(False, description="Activate the result at once")

    @model_validator(mode="after")
    def _known_methods(self) -> SolveIn:
        bad = [m for m in self.methods if m not in ALL_METHODS]
        if bad or not self.methods:
            raise ValueError(
                f"methods must be a non-empty subset of {list(ALL_METHODS)}, got {self.methods}"
            )
        return self

    def to_options(self) -> svc.SolveOptions:
        return svc.SolveOptions(
            intrinsics=IntrinsicsOptions(
                radial_only=self.radial_only,
                k3=self.k3,
                fix_aspect_ratio=self.fix_aspect_ratio,
                reject_outliers=self.reject_outliers,
                min_views=self.min_views,
            ),
            hand_eye=HandEyeOptions(
                methods=tuple(self.methods), refine=self.refine, loss=self.loss
            ),
            intrinsics_source=self.intrinsics,
            activate=self.activate,
        )


class SolveFailedOut(ErrorOut):
    """An error answer; with ?wait=true, a failed solve adds its job."""

    job: JobPublic | None = Field(
        None, description="With ?wait=true, the failed job (absent from other errors)"
    )


@router.post(
    "/sessions/{session_id}/solve",
    summary="Solve the session as a job (202 with the job, or 200/422 with ?wait=true)",
    status_code=status.HTTP_202_ACCEPTED,
    response_class=JSONResponse,
    responses={
        200: {"model": JobOut, "description": "With ?wait=true: the finished job"},
        202: {"model": JobOut, "description": "The job, started"},
        422: {
            "model": SolveFailedOut,
            "description": "A value is out of range, or (with ?wait=true) the solve failed: "
            "too few usable views, degenerate motion (with the failed job)",
        },
        500: {
            "model": SolveFailedOut,
            "description": "A bug in VisionCell (logged); with ?wait=true, with the failed job",
        },
    },
)
async def create_calibration_solve(
    _: EngineerUser,
    session: SessionDep,
    db: DatabaseDep,
    cell: CellDep,
    session_id: DbId,
    body: SolveIn | None = None,
    wait: Annotated[bool, Query(description="Answer when the solve has ended")] = False,
) -> JSONResponse:
    req = body or SolveIn()
    options = req.to_options()
    cal = await svc.get_session(session, session_id)
    svc.check_own("session", cal.id, cal.cell_id, await svc.cell_id_of(session, cell.name))
    warnings = svc.check_solvable(cal, options)  # CalibrationError -> 422 at once

    async def solve(job: Job) -> dict[str, Any]:
        job.report(0.0, f"solving session {session_id}")
        async with db.session() as s:
            out = await svc.solve_session(s, session_id, options, progress=job.report)
            result: dict[str, Any] = {
                "calibration_id": out.calibration.id,
                "kind": out.calibration.kind.value,
                "rms_px": out.calibration.rms_px,
                "active": out.calibration.active,
                "warnings": warnings,
            }
            if out.intrinsic is not None:
                result["intrinsic_calibration_id"] = out.intrinsic.id
        job.report(1.0, f"calibration {result['calibration_id']}: RMS {result['rms_px']:.3f} px")
        return result

    job = cell.jobs.start(
        "calibrate", solve, params={"session_id": session_id, "options": req.model_dump()}
    )
    if not wait:
        return JSONResponse({"job": job.public()}, status_code=status.HTTP_202_ACCEPTED)
    await cell.jobs.wait(job)
    if job.state is JobState.failed and job.error is not None:
        code = 422 if job.error["error"] == "calibration_failed" else 500
        return JSONResponse(
            {**error_body(job.error["error"], job.error["detail"]), "job": job.public()},
            status_code=code,
        )
    return JSONResponse({"job": job.public()}, status_code=status.HTTP_200_OK)
