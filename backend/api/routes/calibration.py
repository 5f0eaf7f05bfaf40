"""Calibration: sessions and their samples (uploads), with the pieces the other calibration
routes share (the board, the answers' shapes, the lookups).  Solving a session:
:mod:`backend.api.routes.calibration_solve`; the stored calibrations (history, reports,
activation): :mod:`backend.api.routes.calibration_history`; automatic calibration:
:mod:`backend.api.routes.calibration_auto`; calibration documents:
:mod:`backend.api.routes.calibration_io`.

Reading needs the viewer role; uploading needs the engineer role.
The work itself is in :mod:`backend.calibration`.
"""

from __future__ import annotations

from pathlib import PurePath
from typing import Annotated, Any, Literal

import cv2
import numpy as np
from fastapi import APIRouter, Depends, File, Form, UploadFile, status
from fastapi.responses import Response
from pydantic import BaseModel, Field, model_validator

from backend import calibration as svc
from backend.api.deps import CellDep, EngineerUser, SessionDep, ViewerUser
from backend.api.errors import ApiError, status_of
from backend.api.schemas import Page
from backend.api.types import (
    MAX_ABS_JOINT_API_RAD,
    DbId,
    DbIndex,
    Limit,
    Offset,
    StrictBool,
    bounded_float,
    bounded_int,
)
from backend.api.uploads import check_image_size, read_capped
from backend.api.work import HeavyWorkDep
from backend.db.models import CalibrationKind
from backend.heavy import HeavyJob
from backend.recognition.images import MAX_IMAGE_BYTES
from vision.calibration import (
    ARUCO_DICTIONARIES,
    MAX_BOARD_SIDE,
    MAX_SQUARE_M,
    MIN_SQUARE_M,
    Board,
    CharucoBoard,
    Chessboard,
)
from vision.calibration.io import parse_poses
from vision.errors import InvalidInput, NotFound

router = APIRouter(prefix="/calibration", tags=["calibration"])

#: File types an upload may contain (by suffix; the content must decode as an image too).
IMAGE_TYPES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
MAX_IMAGES_PER_UPLOAD = 200
#: Largest poses file, bytes (200 poses of 16 numbers take about 80 KB).
MAX_POSES_BYTES = 1 << 20


Side = Annotated[int, bounded_int(3, MAX_BOARD_SIDE, "Count along one side of the board")]
LengthMm = Annotated[
    float,
    bounded_float(MIN_SQUARE_M * 1e3, MAX_SQUARE_M * 1e3, "Length on the board, mm"),
]


class BoardIn(BaseModel):
    """A calibration target; lengths in millimetres."""

    type: Literal["chessboard", "charuco"] = "chessboard"
    cols: Side | None = Field(None, description="Chessboard: inner corners per row")
    rows: Side | None = Field(None, description="Chessboard: inner corners per column")
    squares_x: Side | None = Field(None, description="ChArUco: squares along x")
    squares_y: Side | None = Field(None, description="ChArUco: squares along y")
    square_mm: LengthMm = Field(description="Side of one square, mm")
    marker_mm: LengthMm | None = Field(None, description="ChArUco: marker side, mm")
    dictionary: Literal[ARUCO_DICTIONARIES] = Field(  # type: ignore[valid-type]
        "DICT_5X5_100", description="ChArUco: the ArUco dictionary"
    )
    legacy: StrictBool = False

    @model_validator(mode="after")
    def _complete(self) -> BoardIn:
        if self.type == "chessboard" and (self.cols is None or self.rows is None):
            raise ValueError("a chessboard needs cols and rows (inner corners)")
        if self.type == "charuco" and (
            self.squares_x is None or self.squares_y is None or self.marker_mm is None
        ):
            raise ValueError("a ChArUco board needs squares_x, squares_y and marker_mm")
        try:
            self.to_board()
        except ValueError as exc:  # the board's own checks (marker size, dictionary size)
            raise ValueError(str(exc)) from None
        return self

    def to_board(self) -> Board:
        if self.type == "chessboard":
            assert self.cols is not None and self.rows is not None  # checked above
            return Chessboard(self.cols, self.rows, self.square_mm / 1e3)
        assert self.squares_x is not None and self.squares_y is not None
        assert self.marker_mm is not None
        return CharucoBoard(
            self.squares_x,
            self.squares_y,
            self.square_mm / 1e3,
            self.marker_mm / 1e3,
            self.dictionary,
            self.legacy,
        )


class SessionIn(BaseModel):
    kind: CalibrationKind
    board: BoardIn
    note: str = Field("", max_length=2000)


class SessionOut(BaseModel):
    session: svc.SessionPublic


class SessionDetailOut(BaseModel):
    session: svc.SessionPublic
    samples: list[svc.SamplePublic] = Field(description="By index")
    calibrations: list[svc.CalibrationPublic] = Field(description="Newest first")


class SamplesOut(Page[svc.SamplePublic]):
    """The samples of one upload, in upload order, and how many were accepted."""

    accepted: int
    rejected: int


class CalibrationOut(BaseModel):
    calibration: svc.CalibrationPublic


def _check_upload(name: str, data: bytes) -> tuple[int, int]:
    """(width, height) of an uploaded image from its header: 415 for a file that is not
    an image, 413 for one too large; nothing is decoded."""
    suffix = PurePath(name).suffix.lower()
    if suffix not in IMAGE_TYPES:
        raise ApiError(
            415,
            "unsupported_media_type",
            f"file {name!r} is not an image: upload PNG, JPEG, BMP or TIFF files",
        )
    if not data:
        raise ApiError(415, "unsupported_media_type", f"file {name!r} is empty")
    try:
        return check_image_size(data, name=name)  # bytes and declared pixels, before decoding
    except InvalidInput as exc:
        if status_of(exc) == 413:
            raise
        raise ApiError(
            415, "unsupported_media_type", f"file {name!r} does not decode as an image"
        ) from None


def _decode(name: str, data: bytes) -> np.ndarray:
    """An uploaded image checked by :func:`_check_upload`, decoded (CPU work, in a thread)."""
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ApiError(415, "unsupported_media_type", f"file {name!r} does not decode as an image")
    if img.dtype != np.uint8:
        raise ApiError(
            422, "bad_image", f"image {name!r} must have 8 bits per channel, got {img.dtype}"
        )
    if img.ndim == 3 and img.shape[2] == 4:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2RGB)
    elif img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    return img


def _joints(text: str | None, n: int) -> list[list[float] | None]:
    if not text:
        return [None] * n
    import json

    try:
        rows = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InvalidInput(
            f"joints must be a JSON list of joint vectors (radians): {exc}"
        ) from None
    if not isinstance(rows, list) or len(rows) != n:
        raise InvalidInput(f"joints must list one joint vector per image ({n}), got {text[:80]!r}")
    out: list[list[float] | None] = []
    for k, q in enumerate(rows):
        if (
            not isinstance(q, list)
            or len(q) != 5
            or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in q)
        ):
            raise InvalidInput(f"joints[{k}] must be a list of 5 numbers, got {q!r}")
        if not all(abs(v) <= MAX_ABS_JOINT_API_RAD for v in q):
            raise InvalidInput(
                f"joints[{k}] must be finite, within +-{MAX_ABS_JOINT_API_RAD:.6g} rad, got {q!r}"
            )
        out.append([float(v) for v in q])
    return out


# -- lookups (404 as a dependency) --------------------------------------------------------


async def get_calibration_session(session: SessionDep, session_id: DbId) -> Any:
    """The calibration session with its samples; :class:`NotFound` (404) otherwise."""
    return await svc.get_session(session, session_id)


async def get_calibration_row(session: SessionDep, calibration_id: DbId) -> Any:
    """The calibration; :class:`NotFound` (404) otherwise."""
    return await svc.get_calibration(session, calibration_id)


CalibrationSessionDep = Annotated[Any, Depends(get_calibration_session)]
CalibrationDep = Annotated[Any, Depends(get_calibration_row)]


# -- sessions -----------------------------------------------------------------------------


@router.post(
    "/sessions",
    status_code=status.HTTP_201_CREATED,
    summary="Start a calibration session",
    response_model=SessionOut,
)
async def create_calibration_session(
    _: EngineerUser, session: SessionDep, cell: CellDep, body: SessionIn
) -> dict[str, Any]:
    board = body.board.to_board()
    cell_id = await svc.cell_id_of(session, cell.name)
    row = await svc.create_session(
        session, kind=body.kind, board=board, cell_id=cell_id, note=body.note
    )
    row = await svc.get_session(session, row.id)
    return {"session": svc.SessionPublic.of(row)}


@router.get(
    "/sessions",
    summary="This cell's calibration sessions, newest first",
    response_model=Page[svc.SessionPublic],
)
async def read_calibration_sessions(
    _: ViewerUser, session: SessionDep, cell: CellDep, limit: Limit = 100, offset: Offset = 0
) -> dict[str, Any]:
    cell_id = await svc.cell_id_of(session, cell.name)
    rows = await svc.list_sessions(session, cell_id=cell_id, limit=limit, offset=offset)
    data = [svc.SessionPublic.of(r) for r in rows]
    return {"data": data, "count": await svc.count_sessions(session, cell_id=cell_id)}


@router.get(
    "/sessions/{session_id}",
    summary="One session with its samples and calibrations",
    response_model=SessionDetailOut,
)
async def read_calibration_session(_: ViewerUser, row: CalibrationSessionDep) -> dict[str, Any]:
    cals = sorted(row.calibrations, key=lambda c: c.id, reverse=True)
    return {
        "session": svc.SessionPublic.of(row),
        "samples": [
            svc.SamplePublic.model_validate(s) for s in sorted(row.samples, key=lambda s: s.index)
        ],
        "calibrations": [svc.CalibrationPublic.model_validate(c) for c in cals],
    }


@router.post(
    "/sessions/{session_id}/samples",
    status_code=status.HTTP_201_CREATED,
    summary="Upload images (and robot poses for hand-eye) to a session",
    response_model=SamplesOut,
)
async def create_calibration_samples(
    _: EngineerUser,
    session: SessionDep,
    cell: CellDep,
    work: HeavyWorkDep,
    session_id: DbId,
    images: Annotated[list[UploadFile], File(description="PNG, JPEG, BMP or TIFF images")],
    poses: Annotated[
        UploadFile | None,
        File(description="Text file: one row-major 4x4 T_base_ee per line (metres), one per image"),
    ] = None,
    poses_unit: Annotated[Literal["m", "mm"], Form()] = "m",
    joints: Annotated[
        str | None, Form(description="JSON list of joint vectors (radians), one per image")
    ] = None,
) -> dict[str, Any]:
    cal = await svc.get_session(session, session_id)
    svc.check_own("session", cal.id, cal.cell_id, await svc.cell_id_of(session, cell.name))
    if not images:
        raise InvalidInput("images: upload at least one image")
    if len(images) > MAX_IMAGES_PER_UPLOAD:
        raise ApiError(
            413,
            "too_large",
            f"at most {MAX_IMAGES_PER_UPLOAD} images per upload, got {len(images)}",
        )
    # Decoding and board detection run in the heavy-work pool within the request's pixel
    # budget; a client that leaves drops what is still queued (the unit of work rolls back).
    async with work.job() as job:
        decoded = []
        for f in images:
            name = PurePath(f.filename or "image").name
            data = await read_capped(f, MAX_IMAGE_BYTES)
            w, h = _check_upload(name, data)
            job.take_pixels(w, h, name=name, analysed=True)
            decoded.append((name, await job.run(_decode, name, data)))
        return await _store_samples(session, cal, decoded, poses, poses_unit, joints, job)


async def _store_samples(
    session: Any,
    cal: Any,
    decoded: list[tuple[str, np.ndarray]],
    poses: UploadFile | None,
    poses_unit: str,
    joints: str | None,
    job: HeavyJob,
) -> dict[str, Any]:
    T: list[np.ndarray | None] = [None] * len(decoded)
    if poses is not None:
        raw = await poses.read(MAX_POSES_BYTES + 1)
        if len(raw) > MAX_POSES_BYTES:
            raise ApiError(
                413, "too_large", f"the poses file has more than {MAX_POSES_BYTES} bytes"
            )
        text = raw.decode("utf-8", errors="replace")
        try:
            P = parse_poses(
                text, unit_m=1e-3 if poses_unit == "mm" else 1.0, source=poses.filename or "poses"
            )
        except ValueError as exc:  # the file's content is user input
            raise InvalidInput(str(exc)) from None
        if P.shape[0] != len(decoded):
            raise InvalidInput(
                f"poses has {P.shape[0]} poses but {len(decoded)} images were uploaded: "
                "give one pose per image, in the same order"
            )
        T = list(P)
    q = _joints(joints, len(decoded))
    rows = await svc.add_samples(
        session,
        cal,
        [
            svc.SampleIn(name=n, image=img, joints=q[k], T_base_ee=T[k])
            for k, (n, img) in enumerate(decoded)
        ],
        run=job.run,
    )
    data = [svc.SamplePublic.model_validate(r) for r in rows]
    accepted = sum(1 for r in rows if r.accepted)
    return {
        "data": data,
        "count": len(data),
        "accepted": accepted,
        "rejected": len(data) - accepted,
    }


@router.get(
    "/sessions/{session_id}/samples/{index}/image.png",
    summary="The stored image of a sample",
    response_class=Response,
    responses={200: {"content": {"image/png": {}}, "description": "The image"}},
)
async def read_calibration_sample_image(
    _: ViewerUser, session: SessionDep, session_id: DbId, index: DbIndex
) -> Response:
    # Looked up here, not by a dependency, so that a bad index is a 422 before any 404.
    row = await svc.get_session(session, session_id)
    for s in row.samples:
        if s.index == index:
            return Response(s.image_png, media_type="image/png")
    raise NotFound(f"session {row.id} has no sample {index}")
