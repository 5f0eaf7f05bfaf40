"""The stored calibrations (under ``/api/calibration``): this cell's history, the active
ones, one calibration, its report and plots, activation.

Reading needs the viewer role; activating needs the engineer role and is audited.  The work
itself is in :mod:`backend.calibration`.
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Path, Query
from fastapi.responses import Response
from pydantic import BaseModel

from backend import audit
from backend import calibration as svc
from backend.api.deps import CellDep, EngineerUser, SessionDep, ViewerUser
from backend.api.routes.calibration import CalibrationDep, CalibrationOut
from backend.api.schemas import Page
from backend.api.types import DbId, DbIdQuery, Limit, Offset
from backend.api.work import HeavyWorkDep
from backend.db.models import CalibrationKind

__all__ = ["router"]

router = APIRouter(prefix="/calibration", tags=["calibration"])


class ActiveCalibrationsOut(BaseModel):
    """The active calibration of each kind (None where none is active)."""

    intrinsic: svc.CalibrationPublic | None
    hand_eye: svc.CalibrationPublic | None


PlotName = Annotated[str, Path(max_length=64, description="residuals, coverage or consistency")]


# -- calibrations -------------------------------------------------------------------------


@router.get(
    "/calibrations",
    summary="This cell's calibration history, newest first",
    response_model=Page[svc.CalibrationPublic],
)
async def read_calibrations(
    _: ViewerUser,
    session: SessionDep,
    cell: CellDep,
    kind: CalibrationKind | None = None,
    session_id: DbIdQuery = None,
    limit: Limit = 100,
    offset: Offset = 0,
) -> dict[str, Any]:
    cell_id = await svc.cell_id_of(session, cell.name)
    rows = await svc.history(
        session, cell_id=cell_id, kind=kind, session_id=session_id, limit=limit, offset=offset
    )
    data = [svc.CalibrationPublic.model_validate(r) for r in rows]
    total = await svc.count_history(session, cell_id=cell_id, kind=kind, session_id=session_id)
    return {"data": data, "count": total}


@router.get(
    "/active",
    summary="The active calibration of each kind in this cell",
    response_model=ActiveCalibrationsOut,
)
async def read_active_calibrations(
    _: ViewerUser, session: SessionDep, cell: CellDep
) -> dict[str, Any]:
    cell_id = await svc.cell_id_of(session, cell.name)
    act = await svc.active_calibrations(session, cell_id)
    return {
        k.value: (svc.CalibrationPublic.model_validate(v) if v else None) for k, v in act.items()
    }


@router.get(
    "/calibrations/{calibration_id}", summary="One calibration", response_model=CalibrationOut
)
async def read_calibration(_: ViewerUser, cal: CalibrationDep) -> dict[str, Any]:
    return {"calibration": svc.CalibrationPublic.model_validate(cal)}


@router.get(
    "/calibrations/{calibration_id}/report",
    summary="Report: summary and plot links",
    response_model=svc.CalibrationReport,
)
async def read_calibration_report(_: ViewerUser, cal: CalibrationDep) -> dict[str, Any]:
    return svc.calibration_report(cal)


@router.get(
    "/calibrations/{calibration_id}/report/{plot}.png",
    summary="Report plot: residuals, coverage or consistency (hand-eye)",
    response_class=Response,
    responses={200: {"content": {"image/png": {}}, "description": "The plot"}},
)
async def read_calibration_plot(
    _: ViewerUser, cal: CalibrationDep, work: HeavyWorkDep, plot: PlotName
) -> Response:
    async with work.job() as job:  # rendered in the heavy-work pool
        png = await job.run(svc.report_png, cal, plot)
    return Response(png, media_type="image/png", headers={"Cache-Control": "max-age=3600"})


@router.post(
    "/calibrations/{calibration_id}/activate",
    summary="Make this calibration active",
    response_model=CalibrationOut,
)
async def update_calibration_activate(
    user: EngineerUser,
    session: SessionDep,
    cell: CellDep,
    calibration_id: DbId,
    reason: Annotated[
        str | None, Query(max_length=audit.MAX_REASON_LENGTH, description="Why (audit trail)")
    ] = None,
) -> dict[str, Any]:
    row = await svc.get_calibration(session, calibration_id)
    svc.check_own("calibration", row.id, row.cell_id, await svc.cell_id_of(session, cell.name))
    cal = await svc.activate(session, calibration_id, by=audit.By(audit.Actor.of(user), reason))
    return {"calibration": svc.CalibrationPublic.model_validate(cal)}
