"""The public shapes of stored calibration data: a session, a sample, a calibration and a
calibration's report (what the API answers; no images, no residuals)."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field

from backend.db.models import CalibrationKind, CalibrationSession
from backend.publictypes import IsoTime

__all__ = ["CalibrationPublic", "CalibrationReport", "SamplePublic", "SessionPublic"]


def _count(corners: list[Any] | None) -> int:
    """The number of stored corners (the column holds a list of corners, or None)."""
    return len(corners) if corners else 0


class SamplePublic(BaseModel):
    """One uploaded (or captured) image of a session, without its pixels."""

    model_config = ConfigDict(from_attributes=True)

    index: int = Field(description="Position in the session, from 0")
    name: str = Field(description="File name of the image")
    accepted: bool = Field(description="The board was found in the image")
    reason: str = Field(description="Why the image was rejected (empty when accepted)")
    corner_count: Annotated[int, BeforeValidator(_count)] = Field(
        validation_alias="corners", description="Board corners found"
    )
    joints: list[float] | None = Field(description="Joint values q1..q5 (radians), if given")
    T_base_ee: list[list[float]] | None = Field(
        description="Pose of the flange in the base frame (4x4, metres), if given"
    )
    created_at: IsoTime


SessionStatus = Literal["empty", "collecting", "solved", "active"]


class SessionPublic(BaseModel):
    """A calibration session (no images) with a status derived from its samples and
    calibrations: ``empty`` (no samples), ``collecting`` (not solved yet), ``solved``,
    ``active`` (one of its calibrations is in force)."""

    id: int
    cell_id: int
    kind: CalibrationKind
    source: str = Field(description="upload, or auto (captured by the automatic calibration)")
    board: dict[str, Any] = Field(
        description="The board as stored with the session, lengths in metres: type "
        "chessboard (cols, rows, square_m) or charuco (squares_x, squares_y, square_m, "
        "marker_m, dictionary, legacy); kept as stored, so older sessions may lack type"
    )
    note: str
    created_at: IsoTime
    status: SessionStatus
    sample_count: int
    accepted_count: int
    rejected_count: int
    calibration_ids: list[int] = Field(description="Its calibrations, oldest first")

    @classmethod
    def of(cls, s: CalibrationSession) -> SessionPublic:
        """The summary of a session row loaded with its samples and calibrations."""
        accepted = sum(1 for x in s.samples if x.accepted)
        cals = sorted(s.calibrations, key=lambda c: c.id)
        status: SessionStatus
        if not s.samples:
            status = "empty"
        elif any(c.active for c in cals):
            status = "active"
        elif cals:
            status = "solved"
        else:
            status = "collecting"
        return cls(
            id=s.id,
            cell_id=s.cell_id,
            kind=s.kind,
            source=s.source,
            board=s.board,
            note=s.note,
            created_at=s.created_at,  # IsoTime writes it in ISO form
            status=status,
            sample_count=len(s.samples),
            accepted_count=accepted,
            rejected_count=len(s.samples) - accepted,
            calibration_ids=[c.id for c in cals],
        )


class CalibrationPublic(BaseModel):
    """A stored calibration without its full residuals."""

    model_config = ConfigDict(from_attributes=True)

    id: int
    cell_id: int
    session_id: int | None = Field(description="The session it was solved from (None: imported)")
    kind: CalibrationKind
    active: bool
    rms_px: float | None = Field(description="Reprojection RMS, pixels (None: not known)")
    sample_count: int
    parameters: dict[str, Any] = Field(
        description="The solution; open because it depends on the kind and on where it came "
        "from: intrinsic: K (3x3 px), dist, image_size [w, h]; hand_eye: T_ee_cam (4x4, "
        "metres) with the K, dist, image_size and intrinsics_id it was solved with; an "
        "imported calibration keeps its document's parameters"
    )
    options: dict[str, Any] = Field(
        description="The solve options as given (free-form: they differ by kind)"
    )
    created_at: IsoTime


class CalibrationReport(BaseModel):
    """The report of a solved calibration: the row, a readable summary, links to its plots."""

    calibration: CalibrationPublic
    summary: dict[str, Any] = Field(
        description="Millimetres and degrees for people; its keys depend on the kind: "
        "intrinsic (intrinsics and distortion with their std, per-image RMS, coverage) or "
        "hand_eye (T_ee_cam, consistency, per-pose errors, the solvers' candidates)"
    )
    plots: dict[str, str] = Field(description="Plot name -> URL of its PNG")
