"""Calibration sessions and their samples in the database.

Every function takes an open ``AsyncSession``; the caller's unit of work commits or rolls
back (``Database.session``), so a refused upload leaves no rows behind.  Detection runs in a
worker thread.
"""

from __future__ import annotations

import asyncio
import struct
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray
from sqlalchemy import func, select
from sqlalchemy.ext.asyncio import AsyncSession
from sqlalchemy.orm import selectinload

from backend.calibration.public import SessionPublic
from backend.db.models import CalibrationKind, CalibrationSample, CalibrationSession
from backend.db.models import Cell as CellRow
from vision.calibration import Board, Detection, board_from_dict, check_poses, detect_pattern
from vision.errors import CalibrationError, Conflict, InvalidInput, NotFound

__all__ = [
    "NotFound",
    "OtherCell",
    "ProgressFn",
    "SampleIn",
    "add_samples",
    "cell_id_of",
    "check_own",
    "count_sessions",
    "create_session",
    "get_session",
    "list_sessions",
    "load_detections",
    "png_size",
    "sample_name",
    "session_summary",
]

ProgressFn = Callable[[float, str], None]


class OtherCell(Conflict):
    """The row belongs to another cell: this cell may read it, not change it."""

    code = "other_cell"


def check_own(kind: str, row_id: int, row_cell_id: int, cell_id: int) -> None:
    """Raise :class:`OtherCell` unless the row ``kind row_id`` belongs to cell ``cell_id``."""
    if row_cell_id != cell_id:
        raise OtherCell(
            f"{kind} {row_id} belongs to cell id {row_cell_id}, not to this cell "
            f"(id {cell_id}): change it from its own cell"
        )


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


# -- images and corners ---------------------------------------------------------------------


def _png(image: NDArray[np.uint8]) -> bytes:
    img = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
    ok, buf = cv2.imencode(".png", img)
    if not ok:
        raise CalibrationError("could not encode the image as PNG")
    return buf.tobytes()


def _detect_and_png(image: NDArray[np.uint8], board: Board) -> tuple[Detection, bytes]:
    """The board's detection in ``image`` and the image as PNG (one worker-thread call)."""
    return detect_pattern(image, board), _png(image)


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


def sample_name(s: CalibrationSample) -> str:
    return s.name or f"sample {s.index}"


def load_detections(cal_session: CalibrationSession) -> tuple[list[Detection], list[str]]:
    """The stored detections of a session's samples (in index order) and their names."""
    samples = sorted(cal_session.samples, key=lambda s: s.index)
    return [_detection_of(s) for s in samples], [sample_name(s) for s in samples]


# -- sessions and samples -----------------------------------------------------------------


async def cell_id_of(session: AsyncSession, name: str) -> int:
    """Id of the cell called ``name`` (``Settings.cell_name`` of the process that runs it)."""
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
        raise InvalidInput(
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
    run: Callable[..., Awaitable[Any]] | None = None,
) -> list[CalibrationSample]:
    """Detect the board in each image and store every sample, accepted or rejected with the
    reason.  Hand-eye sessions need ``T_base_ee`` on every sample (else ``InvalidInput``,
    nothing stored).  ``run`` runs each image's detection (a request's heavy-work job,
    :meth:`backend.heavy.HeavyJob.run`; None: ``asyncio.to_thread``)."""
    run = run or asyncio.to_thread
    if not samples:
        raise InvalidInput("samples must not be empty")
    board = board_from_dict(cal_session.board)
    poses: list[NDArray[np.float64] | None] = []
    for k, s in enumerate(samples):
        if s.T_base_ee is None:
            if cal_session.kind is CalibrationKind.hand_eye:
                raise InvalidInput(
                    f"sample {s.name!r} has no robot pose: hand-eye sessions need T_base_ee "
                    "for every image"
                )
            poses.append(None)
        else:
            poses.append(check_poses(np.asarray(s.T_base_ee)[None], f"T_base_ee of {s.name!r}")[0])
        if s.joints is not None:
            q = np.asarray(s.joints, dtype=np.float64).ravel()
            if not np.all(np.isfinite(q)):
                raise InvalidInput(f"joints of sample {s.name!r} must be finite, got {q.tolist()}")
        if k > 0 and samples[0].image.shape[:2] != s.image.shape[:2]:
            raise InvalidInput(
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
            raise InvalidInput(
                f"images of one session must have one size: the session holds {w}x{h}, "
                f"{samples[0].name!r} is {first[1]}x{first[0]}"
            )
    if start is None:  # COALESCE(..., -1) always gives a row
        raise RuntimeError("the sample-index query returned no value")
    rows = []
    for k, s in enumerate(samples):
        det, png = await run(_detect_and_png, s.image, board)
        reason = f"{det.n_points} corners ({det.method} detector)" if det.found else det.reason
        row = CalibrationSample(
            session_id=cal_session.id,
            index=int(start) + 1 + k,
            name=s.name[:255],
            image_png=png,
            joints=None if s.joints is None else [float(v) for v in s.joints],
            T_base_ee=None if (pose := poses[k]) is None else pose.tolist(),
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


async def count_sessions(session: AsyncSession, *, cell_id: int | None = None) -> int:
    """How many sessions :func:`list_sessions` pages through."""
    q = select(func.count()).select_from(CalibrationSession)
    if cell_id is not None:
        q = q.where(CalibrationSession.cell_id == cell_id)
    return int(await session.scalar(q) or 0)


def session_summary(s: CalibrationSession) -> dict[str, Any]:
    """JSON summary of a session (no images) with its derived status
    (:class:`SessionPublic`)."""
    return SessionPublic.of(s).model_dump(mode="json")
