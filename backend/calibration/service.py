"""Calibration sessions in the database: samples, solutions, re-solving, activation, history.

Every function takes an open ``AsyncSession``; the caller's unit of work commits or rolls
back (``Database.session``), so a failed solve or a refused upload leaves no rows behind.
CPU-heavy work (detection, solving) runs in a worker thread.
"""

from __future__ import annotations

import asyncio
import struct
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray
from sqlalchemy import func, select
from sqlalchemy.ext.asyncio import AsyncSession

from backend.db.models import Calibration, CalibrationKind, CalibrationSample, CalibrationSession
from backend.db.models import Cell as CellRow
from vision.calibration import (
    Board,
    Detection,
    HandEyeOptions,
    HandEyeResult,
    IntrinsicsOptions,
    IntrinsicsResult,
    board_from_dict,
    calibrate_hand_eye,
    calibrate_intrinsics_from_detections,
    check_poses,
    detect_pattern,
    motion_warnings,
    rotation_diversity,
)
from vision.camera import PinholeCamera
from vision.errors import CalibrationError, VisionCellError

__all__ = [
    "NotFound",
    "SampleIn",
    "SolveOptions",
    "SolveOutcome",
    "activate",
    "active_calibrations",
    "add_samples",
    "cell_id_of",
    "check_solvable",
    "create_session",
    "get_calibration",
    "get_session",
    "history",
    "list_sessions",
    "load_detections",
    "result_of",
    "session_summary",
    "solve_session",
]

ProgressFn = Callable[[float, str], None]


class NotFound(VisionCellError):
    """No row with that id."""

    code = "not_found"
    http_status = 404


@dataclass(frozen=True)
class SampleIn:
    """One image to add to a session.

    Attributes
    ----------
    name : str
        File name or label, shown in reports.
    image : ndarray of shape (H, W) or (H, W, 3), uint8
        Greyscale or RGB.
    joints : sequence of float, optional
        The arm's joint state (radians) when the image was taken.
    T_base_ee : ndarray of shape (4, 4), optional
        The flange pose (metres); required for hand-eye sessions.
    """

    name: str
    image: NDArray[np.uint8]
    joints: Sequence[float] | None = None
    T_base_ee: NDArray[np.float64] | None = None


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


# -- images and corners ---------------------------------------------------------------------


def _png(image: NDArray[np.uint8]) -> bytes:
    img = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
    ok, buf = cv2.imencode(".png", img)
    if not ok:
        raise CalibrationError("could not encode the image as PNG")
    return buf.tobytes()


def png_size(data: bytes) -> tuple[int, int]:
    """``(width, height)`` from a PNG's header."""
    if len(data) < 24 or data[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError("not a PNG image")
    w, h = struct.unpack(">II", data[16:24])
    return int(w), int(h)


def _corners_json(d: Detection) -> list[list[float]] | None:
    if not d.found:
        return None
    return [[int(i), float(u), float(v)] for i, (u, v) in zip(d.ids, d.image_points, strict=True)]


def _detection_of(sample: CalibrationSample) -> Detection:
    size = png_size(sample.image_png)
    if not sample.accepted or not sample.corners:
        return Detection.missing(size, sample.reason or "pattern not found")
    arr = np.asarray(sample.corners, dtype=np.float64).reshape(-1, 3)
    return Detection(True, arr[:, 1:3].copy(), arr[:, 0].astype(np.int64), size, "stored", "")


def _sample_name(s: CalibrationSample) -> str:
    return s.name or f"sample {s.index}"


def load_detections(cal_session: CalibrationSession) -> tuple[list[Detection], list[str]]:
    """The stored detections of a session's samples (in index order) and their names."""
    samples = sorted(cal_session.samples, key=lambda s: s.index)
    return [_detection_of(s) for s in samples], [_sample_name(s) for s in samples]


# -- sessions and samples -----------------------------------------------------------------


async def cell_id_of(session: AsyncSession, name: str | None = None) -> int:
    """Id of the cell called ``name`` (default: this process's cell)."""
    if name is None:
        from backend.app import DEFAULT_CELL  # imported here: backend.app imports the API

        name = DEFAULT_CELL
    cell_id = await session.scalar(select(CellRow.id).where(CellRow.name == name))
    if cell_id is None:
        raise NotFound(f"no cell named {name!r}")
    return int(cell_id)


async def create_session(
    session: AsyncSession,
    *,
    kind: CalibrationKind,
    board: Board,
    cell_id: int,
    source: str = "upload",
    note: str = "",
) -> CalibrationSession:
    """Start a calibration session of ``kind`` with ``board`` for cell ``cell_id``."""
    if source not in ("upload", "auto"):
        raise ValueError(f"source must be 'upload' or 'auto', got {source!r}")
    if kind is CalibrationKind.hand_eye and not board.orientation_unique:
        raise ValueError(
            f"board {board.describe()} has no unique frame (square pattern, or rows + cols "
            "even): hand-eye calibration needs one; use e.g. 9x6 or a ChArUco board"
        )
    row = CalibrationSession(
        cell_id=cell_id, kind=kind, source=source, board=board.as_dict(), note=note
    )
    session.add(row)
    await session.flush()
    return row


async def get_session(session: AsyncSession, session_id: int) -> CalibrationSession:
    """The session with its samples; :class:`NotFound` if there is none."""
    from sqlalchemy.orm import selectinload

    row = await session.scalar(
        select(CalibrationSession)
        .where(CalibrationSession.id == session_id)
        .options(
            selectinload(CalibrationSession.samples), selectinload(CalibrationSession.calibrations)
        )
    )
    if row is None:
        raise NotFound(f"no calibration session with id {session_id}")
    return row


async def add_samples(
    session: AsyncSession,
    cal_session: CalibrationSession,
    samples: Sequence[SampleIn],
    *,
    progress: ProgressFn | None = None,
) -> list[CalibrationSample]:
    """Detect the board in each image and store every sample, accepted or rejected with the
    reason.  Hand-eye sessions need ``T_base_ee`` on every sample (else ``ValueError``,
    nothing stored)."""
    if not samples:
        raise ValueError("samples must not be empty")
    board = board_from_dict(cal_session.board)
    poses: list[NDArray[np.float64] | None] = []
    for k, s in enumerate(samples):
        if s.T_base_ee is None:
            if cal_session.kind is CalibrationKind.hand_eye:
                raise ValueError(
                    f"sample {s.name!r} has no robot pose: hand-eye sessions need T_base_ee "
                    "for every image"
                )
            poses.append(None)
        else:
            poses.append(check_poses(np.asarray(s.T_base_ee)[None], f"T_base_ee of {s.name!r}")[0])
        if s.joints is not None:
            q = np.asarray(s.joints, dtype=np.float64).ravel()
            if not np.all(np.isfinite(q)):
                raise ValueError(f"joints of sample {s.name!r} must be finite, got {q.tolist()}")
        if k > 0 and samples[0].image.shape[:2] != s.image.shape[:2]:
            raise ValueError(
                f"images of one session must have one size: {samples[0].name!r} is "
                f"{samples[0].image.shape[1]}x{samples[0].image.shape[0]}, {s.name!r} is "
                f"{s.image.shape[1]}x{s.image.shape[0]}"
            )
    start = await session.scalar(
        select(func.coalesce(func.max(CalibrationSample.index), -1)).where(
            CalibrationSample.session_id == cal_session.id
        )
    )
    existing = await session.scalar(
        select(CalibrationSample.image_png)
        .where(CalibrationSample.session_id == cal_session.id)
        .limit(1)
    )
    if existing is not None:
        w, h = png_size(existing)
        first = samples[0].image.shape
        if (first[1], first[0]) != (w, h):
            raise ValueError(
                f"images of one session must have one size: the session holds {w}x{h}, "
                f"{samples[0].name!r} is {first[1]}x{first[0]}"
            )
    rows = []
    for k, s in enumerate(samples):
        det, png = await asyncio.to_thread(
            lambda img=s.image: (detect_pattern(img, board), _png(img))
        )
        reason = f"{det.n_points} corners ({det.method} detector)" if det.found else det.reason
        row = CalibrationSample(
            session_id=cal_session.id,
            index=int(start) + 1 + k,
            name=s.name[:255],
            image_png=png,
            joints=None if s.joints is None else [float(v) for v in s.joints],
            T_base_ee=None if poses[k] is None else poses[k].tolist(),
            corners=_corners_json(det),
            accepted=det.found,
            reason=reason,
        )
        session.add(row)
        rows.append(row)
        if progress is not None:
            progress((k + 1) / len(samples), f"{s.name}: {reason}")
    await session.flush()
    return rows


async def list_sessions(
    session: AsyncSession, *, cell_id: int | None = None, limit: int = 100, offset: int = 0
) -> list[CalibrationSession]:
    """Sessions, newest first, with samples and calibrations loaded."""
    from sqlalchemy.orm import selectinload

    q = (
        select(CalibrationSession)
        .options(
            selectinload(CalibrationSession.samples), selectinload(CalibrationSession.calibrations)
        )
        .order_by(CalibrationSession.id.desc())
        .limit(limit)
        .offset(offset)
    )
    if cell_id is not None:
        q = q.where(CalibrationSession.cell_id == cell_id)
    return list((await session.scalars(q)).all())


def session_summary(s: CalibrationSession) -> dict[str, Any]:
    """JSON summary of a session (no images) with a derived status:
    ``empty`` (no samples), ``collecting`` (not solved yet), ``solved``, ``active``
    (one of its calibrations is in force)."""
    accepted = sum(1 for x in s.samples if x.accepted)
    cals = sorted(s.calibrations, key=lambda c: c.id)
    if not s.samples:
        status = "empty"
    elif any(c.active for c in cals):
        status = "active"
    elif cals:
        status = "solved"
    else:
        status = "collecting"
    return {
        "id": s.id,
        "cell_id": s.cell_id,
        "kind": s.kind.value,
        "source": s.source,
        "board": s.board,
        "note": s.note,
        "created_at": s.created_at.isoformat(),
        "status": status,
        "sample_count": len(s.samples),
        "accepted_count": accepted,
        "rejected_count": len(s.samples) - accepted,
        "calibration_ids": [c.id for c in cals],
    }


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
        rejected = [f"{_sample_name(s)}: {s.reason}" for s in cal_session.samples if not s.accepted]
        raise CalibrationError(
            f"need at least {need} images with the board, the session has {len(accepted)} of "
            f"{len(cal_session.samples)}"
            + (f" (rejected: {'; '.join(rejected)})" if rejected else "")
        )
    if cal_session.kind is CalibrationKind.hand_eye:
        return motion_warnings(rotation_diversity(_accepted_poses(cal_session)), options.hand_eye)
    return []


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


# -- activation and history ---------------------------------------------------------------


async def _make_active(session: AsyncSession, cal: Calibration) -> None:
    others = await session.scalars(
        select(Calibration).where(
            Calibration.cell_id == cal.cell_id,
            Calibration.kind == cal.kind,
            Calibration.active,
            Calibration.id != cal.id,
        )
    )
    for o in others:
        o.active = False
    # Clear the old one first: the partial unique index allows one active row at a time.
    await session.flush()
    cal.active = True
    await session.flush()


async def activate(session: AsyncSession, calibration_id: int) -> Calibration:
    """Make a calibration the active one of its kind in its cell (the previous one is
    deactivated).  A hand-eye calibration brings the intrinsics it was solved with along:
    ``T_ee_cam`` holds only with them."""
    cal = await get_calibration(session, calibration_id)
    if cal.kind is CalibrationKind.hand_eye:
        intr_id = cal.parameters.get("intrinsics_id")
        if intr_id is not None:
            intr = await session.get(Calibration, int(intr_id))
            if intr is not None:
                await _make_active(session, intr)
    await _make_active(session, cal)
    return cal


async def history(
    session: AsyncSession,
    *,
    cell_id: int | None = None,
    kind: CalibrationKind | None = None,
    session_id: int | None = None,
    limit: int = 100,
) -> list[Calibration]:
    """Calibrations, newest first."""
    q = select(Calibration).order_by(Calibration.id.desc()).limit(limit)
    if cell_id is not None:
        q = q.where(Calibration.cell_id == cell_id)
    if kind is not None:
        q = q.where(Calibration.kind == kind)
    if session_id is not None:
        q = q.where(Calibration.session_id == session_id)
    return list((await session.scalars(q)).all())


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
