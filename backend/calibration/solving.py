"""Solving calibration sessions from their stored samples.

A solve reads the stored corners (not the images), so the same samples with the same
options give the same numbers; each solve adds calibration rows.  A failed solve raises
before anything is written, or inside the caller's unit of work, which then rolls back.
Activation and history are in :mod:`backend.calibration.activation`, re-exported here.
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from sqlalchemy import select
from sqlalchemy.ext.asyncio import AsyncSession

from backend.calibration.activation import (
    CameraCalibration,
    activate,
    active_calibrations,
    active_camera_calibration,
    count_history,
    get_calibration,
    history,
    result_of,
)
from backend.calibration.sessions import ProgressFn, get_session, load_detections, sample_name
from backend.db.models import Calibration, CalibrationKind, CalibrationSession
from vision.calibration import (
    HandEyeOptions,
    IntrinsicsOptions,
    IntrinsicsResult,
    board_from_dict,
    calibrate_hand_eye,
    calibrate_intrinsics_from_detections,
    motion_warnings,
    rotation_diversity,
)
from vision.camera import PinholeCamera
from vision.errors import CalibrationError

__all__ = [
    "CameraCalibration",
    "SolveOptions",
    "SolveOutcome",
    "activate",
    "active_calibrations",
    "active_camera_calibration",
    "check_solvable",
    "count_history",
    "get_calibration",
    "history",
    "result_of",
    "solve_session",
]


@dataclass(frozen=True)
class SolveOptions:
    """Options of one solve of a session (stored with the calibration it produces).

    Attributes
    ----------
    intrinsics : IntrinsicsOptions
        Model and outlier handling of the intrinsic solve.
    hand_eye : HandEyeOptions
        Solvers and refinement of the hand-eye solve.
    intrinsics_source : str or int
        For hand-eye sessions: ``"session"`` solves the intrinsics from the session's own
        images (and stores them as an intrinsic calibration too), ``"active"`` uses the
        cell's active intrinsic calibration, an int uses that calibration.
    activate : bool
        Make the result the active calibration of its kind at once.
    """

    intrinsics: IntrinsicsOptions = field(default_factory=IntrinsicsOptions)
    hand_eye: HandEyeOptions = field(default_factory=HandEyeOptions)
    intrinsics_source: str | int = "session"
    activate: bool = False

    def __post_init__(self) -> None:
        src = self.intrinsics_source
        if not (src in ("session", "active") or (isinstance(src, int) and src > 0)):
            raise ValueError(
                f"intrinsics_source must be 'session', 'active' or a calibration id, got {src!r}"
            )

    def as_dict(self, kind: CalibrationKind) -> dict[str, Any]:
        """JSON form of the options that matter for ``kind``."""
        d: dict[str, Any] = {"intrinsics": self.intrinsics.as_dict()}
        if kind is CalibrationKind.hand_eye:
            d["hand_eye"] = self.hand_eye.as_dict()
            d["intrinsics_source"] = self.intrinsics_source
        return d


@dataclass(frozen=True)
class SolveOutcome:
    """The calibration rows a solve produced (``intrinsic`` is None when not solved)."""

    calibration: Calibration
    intrinsic: Calibration | None


# -- solving ------------------------------------------------------------------------------


def _accepted_poses(cal_session: CalibrationSession) -> NDArray[np.float64]:
    rows = [s for s in sorted(cal_session.samples, key=lambda s: s.index) if s.accepted]
    return np.array([s.T_base_ee for s in rows if s.T_base_ee is not None]).reshape(-1, 4, 4)


def check_solvable(cal_session: CalibrationSession, options: SolveOptions) -> list[str]:
    """Cheap checks before a solve job starts: enough accepted samples and, for hand-eye,
    motion that is not degenerate.  Returns motion warnings; raises
    :class:`CalibrationError` with the reason otherwise."""
    accepted = [s for s in cal_session.samples if s.accepted]
    need = (
        options.intrinsics.min_views
        if cal_session.kind is CalibrationKind.intrinsic
        else options.hand_eye.min_poses
    )
    if len(accepted) < need:
        rejected = [f"{sample_name(s)}: {s.reason}" for s in cal_session.samples if not s.accepted]
        raise CalibrationError(
            f"need at least {need} images with the board, the session has {len(accepted)} of "
            f"{len(cal_session.samples)}"
            + (f" (rejected: {'; '.join(rejected)})" if rejected else "")
        )
    if cal_session.kind is CalibrationKind.hand_eye:
        return motion_warnings(rotation_diversity(_accepted_poses(cal_session)), options.hand_eye)
    return []


async def _intrinsics_for(
    session: AsyncSession, cal_session: CalibrationSession, options: SolveOptions
) -> tuple[PinholeCamera, int | None]:
    src = options.intrinsics_source
    if src == "active":
        row = await session.scalar(
            select(Calibration).where(
                Calibration.cell_id == cal_session.cell_id,
                Calibration.kind == CalibrationKind.intrinsic,
                Calibration.active,
            )
        )
        if row is None:
            raise CalibrationError(
                "intrinsics_source is 'active' but the cell has no active intrinsic calibration"
            )
    else:
        row = await session.get(Calibration, int(src))
        if row is None or row.kind is not CalibrationKind.intrinsic:
            raise CalibrationError(f"no intrinsic calibration with id {src}")
    p = row.parameters
    w, h = p["image_size"]
    return PinholeCamera(p["K"], p["dist"], width=int(w), height=int(h)), row.id


def _intrinsic_row(
    cal_session: CalibrationSession, result: IntrinsicsResult, options: dict[str, Any]
) -> Calibration:
    return Calibration(
        cell_id=cal_session.cell_id,
        session_id=cal_session.id,
        kind=CalibrationKind.intrinsic,
        parameters={
            "K": result.K.tolist(),
            "dist": result.dist.tolist(),
            "image_size": list(result.image_size),
        },
        residuals=result.as_dict(),
        options=options,
        sample_count=len(result.views),
        rms_px=result.rms_px,
        active=False,
    )


async def solve_session(
    session: AsyncSession,
    session_id: int,
    options: SolveOptions | None = None,
    *,
    progress: ProgressFn | None = None,
) -> SolveOutcome:
    """Solve a session from its stored samples and store the solution(s).

    The same stored samples and the same options give the same answer (the solvers are
    deterministic), so a session can be solved again later with other options; every solve
    adds calibration rows (the history).  Nothing is activated unless ``options.activate``.

    Raises
    ------
    CalibrationError
        Too few usable views, degenerate motion, or missing intrinsics.  No row is added.
    """
    opts = options or SolveOptions()
    cal_session = await get_session(session, session_id)
    check_solvable(cal_session, opts)
    board = board_from_dict(cal_session.board)
    detections, names = load_detections(cal_session)

    def report(f: float, msg: str) -> None:
        if progress is not None:
            progress(f, msg)

    if cal_session.kind is CalibrationKind.intrinsic:
        result = await asyncio.to_thread(
            calibrate_intrinsics_from_detections,
            detections,
            board,
            names=names,
            options=opts.intrinsics,
            progress=report,
        )
        row = _intrinsic_row(cal_session, result, opts.as_dict(cal_session.kind))
        session.add(row)
        await session.flush()
        if opts.activate:
            await activate(session, row.id)
        return SolveOutcome(row, None)

    samples = sorted(cal_session.samples, key=lambda s: s.index)
    poses = np.array(
        [s.T_base_ee if s.T_base_ee is not None else np.eye(4).tolist() for s in samples]
    )
    intrinsic_row: Calibration | None = None
    if opts.intrinsics_source == "session":
        intr = await asyncio.to_thread(
            calibrate_intrinsics_from_detections,
            detections,
            board,
            names=names,
            options=opts.intrinsics,
            progress=lambda f, m: report(0.4 * f, m),
        )
        camera, intr_id = intr.camera, None
        intrinsic_row = _intrinsic_row(cal_session, intr, {"intrinsics": opts.intrinsics.as_dict()})
        session.add(intrinsic_row)
        await session.flush()
        intr_id = intrinsic_row.id
    else:
        camera, intr_id = await _intrinsics_for(session, cal_session, opts)
        size = detections[0].image_size
        if (camera.width, camera.height) != size:
            raise CalibrationError(
                f"the intrinsic calibration {intr_id} is for {camera.width}x{camera.height} "
                f"images but this session's are {size[0]}x{size[1]}"
            )
    he = await asyncio.to_thread(
        calibrate_hand_eye,
        detections,
        poses,
        board,
        camera,
        names=names,
        options=opts.hand_eye,
        progress=lambda f, m: report(0.4 + 0.6 * f, m),
    )
    row = Calibration(
        cell_id=cal_session.cell_id,
        session_id=cal_session.id,
        kind=CalibrationKind.hand_eye,
        parameters={
            "T_ee_cam": he.T_ee_cam.tolist(),
            "K": he.K.tolist(),
            "dist": he.dist.tolist(),
            "image_size": [camera.width, camera.height],
            "intrinsics_id": intr_id,
        },
        residuals=he.as_dict(),
        options=opts.as_dict(cal_session.kind),
        sample_count=len(he.poses),
        rms_px=he.rms_px,
        active=False,
    )
    session.add(row)
    await session.flush()
    if opts.activate:
        await activate(session, row.id)
    return SolveOutcome(row, intrinsic_row)
