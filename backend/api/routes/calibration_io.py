"""Calibration documents: export a stored calibration, import one from another cell or tool.

Exporting needs the viewer role; importing needs the engineer role and is audited.  The
document and its checks are in :mod:`backend.calibration.transfer`.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import APIRouter, status
from pydantic import BaseModel, ConfigDict, Field

from backend import audit
from backend import calibration as svc
from backend.api.deps import CellDep, EngineerUser, SessionDep, ViewerUser
from backend.api.routes.calibration import CalibrationDep, CalibrationOut
from backend.api.types import StrictBool, bounded_float, bounded_int
from backend.calibration import transfer
from backend.db.models import CalibrationKind

router = APIRouter(prefix="/calibration", tags=["calibration"])


class CalibrationDocument(BaseModel):
    """A calibration as exported by ``GET /calibration/calibrations/{id}/export``."""

    model_config = ConfigDict(extra="forbid")

    format: Literal["visioncell-calibration"] = Field(description="Always visioncell-calibration")
    version: Literal[1] = Field(description="Version of the document's format")
    kind: CalibrationKind
    parameters: dict[str, Any] = Field(
        description="intrinsic: K (3x3 px), dist (4, 5, 8, 12 or 14 terms), image_size "
        "[w, h]; hand_eye: T_ee_cam (4x4, metres), optionally with its K, dist, image_size"
    )
    sample_count: Annotated[
        int, bounded_int(0, transfer.MAX_SAMPLES, "Images the calibration was solved from")
    ] = 0
    rms_px: (
        Annotated[float, bounded_float(0.0, transfer.MAX_RMS_PX, "Reprojection RMS, pixels")] | None
    ) = None
    source: dict[str, Any] | None = Field(None, description="Where the calibration came from")


class CalibrationImportIn(CalibrationDocument):
    activate: StrictBool = Field(False, description="Activate it at once (same transaction)")
    reason: str | None = Field(
        None, max_length=audit.MAX_REASON_LENGTH, description="Why (audit trail)"
    )


@router.get(
    "/calibrations/{calibration_id}/export",
    summary="One calibration as a document that import takes back",
    response_model=CalibrationDocument,
)
async def read_calibration_export(
    _: ViewerUser, session: SessionDep, cal: CalibrationDep
) -> dict[str, Any]:
    return await transfer.export_document(session, cal)


@router.post(
    "/calibrations/import",
    status_code=status.HTTP_201_CREATED,
    summary="Import a calibration document into this cell (optionally activating it)",
    response_model=CalibrationOut,
)
async def create_calibration_import(
    user: EngineerUser,
    session: SessionDep,
    cell: CellDep,
    body: CalibrationImportIn,
) -> dict[str, Any]:
    doc = {**body.model_dump(exclude={"activate", "reason"}), "kind": body.kind.value}
    checked = transfer.check_document(doc)  # InvalidInput -> 422 naming the value
    row = await transfer.import_calibration(
        session,
        await svc.cell_id_of(session, cell.name),
        checked,
        make_active=body.activate,
        by=audit.By(audit.Actor.of(user), body.reason),
    )
    return {"calibration": svc.CalibrationPublic.model_validate(row)}
