"""Solved calibrations as stored: one by id and its result object, activation (at most one
active of each kind per cell, audited), the history, and the active camera model of a
cell."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from sqlalchemy import func, select
from sqlalchemy.ext.asyncio import AsyncSession

from backend import audit
from backend.calibration.sessions import NotFound
from backend.db.models import Calibration, CalibrationKind
from vision.calibration import HandEyeResult, IntrinsicsResult
from vision.camera import PinholeCamera


async def get_calibration(session: AsyncSession, calibration_id: int) -> Calibration:
    """The calibration row; :class:`NotFound` if there is none."""
    row = await session.get(Calibration, calibration_id)
    if row is None:
        raise NotFound(f"no calibration with id {calibration_id}")
    return row


def result_of(cal: Calibration) -> IntrinsicsResult | HandEyeResult:
    """The stored solution as its result object (for reports)."""
    if cal.kind is CalibrationKind.intrinsic:
        return IntrinsicsResult.from_dict(cal.residuals)
    return HandEyeResult.from_dict(cal.residuals)


# -- activation and history ---------------------------------------------------------------


async def _make_active(session: AsyncSession, cal: Calibration, by: audit.By) -> None:
    was_active = cal.active
    others = await session.scalars(
        select(Calibration).where(
            Calibration.cell_id == cal.cell_id,
            Calibration.kind == cal.kind,
            Calibration.active,
            Calibration.id != cal.id,
        )
    )
    previous = list(others)
    for o in previous:
        o.active = False
    # Clear the old one first: the partial unique index allows one active row at a time.
    await session.flush()
    cal.active = True
    await session.flush()
    if was_active and not previous:
        return  # already the active one: nothing changed, nothing to record
    where = {"cell_id": cal.cell_id, "kind": cal.kind.value}
    audit.record(
        session,
        actor=by.actor,
        kind="calibration",
        entity_id=cal.id,
        action="activate",
        old={**where, "active_id": previous[0].id if previous else None},
        new={**where, "active_id": cal.id, "rms_px": cal.rms_px},
        reason=by.reason,
    )


async def activate(
    session: AsyncSession, calibration_id: int, *, by: audit.By | None = None
) -> Calibration:
    """Make a calibration the active one of its kind in its cell (the previous one is
    deactivated).  A hand-eye calibration brings the intrinsics it was solved with along:
    ``T_ee_cam`` holds only with them."""
    by = by or audit.By()
    cal = await get_calibration(session, calibration_id)
    if cal.kind is CalibrationKind.hand_eye:
        intr_id = cal.parameters.get("intrinsics_id")
        if intr_id is not None:
            intr = await session.get(Calibration, int(intr_id))
            if intr is not None:
                await _make_active(session, intr, by)
    await _make_active(session, cal, by)
    return cal


def _history_filter(q, *, cell_id, kind, session_id):
    if cell_id is not None:
        q = q.where(Calibration.cell_id == cell_id)
    if kind is not None:
        q = q.where(Calibration.kind == kind)
    if session_id is not None:
        q = q.where(Calibration.session_id == session_id)
    return q


async def history(
    session: AsyncSession,
    *,
    cell_id: int | None = None,
    kind: CalibrationKind | None = None,
    session_id: int | None = None,
    limit: int = 100,
    offset: int = 0,
) -> list[Calibration]:
    """Calibrations, newest first (``limit`` of them after skipping ``offset``)."""
    q = select(Calibration).order_by(Calibration.id.desc()).limit(limit).offset(offset)
    q = _history_filter(q, cell_id=cell_id, kind=kind, session_id=session_id)
    return list((await session.scalars(q)).all())


async def count_history(
    session: AsyncSession,
    *,
    cell_id: int | None = None,
    kind: CalibrationKind | None = None,
    session_id: int | None = None,
) -> int:
    """How many calibrations :func:`history` pages through."""
    q = select(func.count()).select_from(Calibration)
    q = _history_filter(q, cell_id=cell_id, kind=kind, session_id=session_id)
    return int(await session.scalar(q) or 0)


async def active_calibrations(
    session: AsyncSession, cell_id: int
) -> dict[CalibrationKind, Calibration | None]:
    """The active calibration of each kind in the cell (None where there is none)."""
    rows = (
        await session.scalars(
            select(Calibration).where(Calibration.cell_id == cell_id, Calibration.active)
        )
    ).all()
    out: dict[CalibrationKind, Calibration | None] = dict.fromkeys(CalibrationKind)
    for r in rows:
        out[r.kind] = r
    return out


@dataclass(frozen=True)
class CameraCalibration:
    """What the rest of the cell needs from the active calibrations.

    Attributes
    ----------
    camera : PinholeCamera or None
        The active intrinsics (eqs. 1-5), None if none is active.
    T_ee_cam : ndarray of shape (4, 4) or None
        The active hand-eye transform (inverse of eq. 12's H), metres.
    intrinsic_id, hand_eye_id : int or None
        The calibration rows they come from.
    """

    camera: PinholeCamera | None
    T_ee_cam: NDArray[np.float64] | None
    intrinsic_id: int | None
    hand_eye_id: int | None


async def active_camera_calibration(session: AsyncSession, cell_id: int) -> CameraCalibration:
    """The cell's active camera model and ``T_ee_cam`` (for recognition and pose estimation)."""
    act = await active_calibrations(session, cell_id)
    intr, he = act[CalibrationKind.intrinsic], act[CalibrationKind.hand_eye]
    camera = None
    if intr is not None:
        w, h = intr.parameters["image_size"]
        camera = PinholeCamera(
            intr.parameters["K"], intr.parameters["dist"], width=int(w), height=int(h)
        )
    T = None if he is None else np.asarray(he.parameters["T_ee_cam"], dtype=np.float64)
    return CameraCalibration(
        camera, T, None if intr is None else intr.id, None if he is None else he.id
    )
