"""Calibration: sessions and their samples (uploads), solve jobs, reports, activation, history.

Reading needs the viewer role; uploading, solving and activating need the engineer role.
The work itself is in :mod:`backend.calibration`.
"""

from __future__ import annotations

from pathlib import PurePath
from typing import Annotated, Any, Literal

import cv2
import numpy as np
from fastapi import APIRouter, Depends, File, Form, Path, Query, UploadFile, status
from fastapi.responses import JSONResponse, Response
from pydantic import BaseModel, Field, model_validator

from backend import audit
from backend import calibration as svc
from backend.api.deps import CellDep, DatabaseDep, EngineerUser, SessionDep, SimDep, ViewerUser
from backend.api.errors import ApiError, error_body, status_of
from backend.api.schemas import JobOut, Page
from backend.api.types import (
    MAX_ABS_JOINT_API_RAD,
    MAX_DB_ID,
    DbId,
    DbIdQuery,
    DbIndex,
    Limit,
    Matrix4,
    Offset,
    Speed,
    StrictBool,
    bounded_float,
    bounded_int,
)
from backend.api.uploads import check_image_size, read_capped
from backend.api.work import HeavyWorkDep
from backend.db.models import CalibrationKind
from backend.heavy import HeavyJob
from backend.jobs import Job, JobState
from backend.recognition.images import MAX_IMAGE_BYTES
from robot.collision import CollisionWorld
from vision.calibration import (
    ALL_METHODS,
    ARUCO_DICTIONARIES,
    MAX_BOARD_SIDE,
    MAX_SQUARE_M,
    MIN_SQUARE_M,
    Board,
    CharucoBoard,
    Chessboard,
    HandEyeOptions,
    IntrinsicsOptions,
)
from vision.calibration.io import parse_poses
from vision.errors import InvalidInput, NotFound

router = APIRouter(prefix="/calibration", tags=["calibration"])

#: File types an upload may contain (by suffix; the content must decode as an image too).
IMAGE_TYPES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
MAX_IMAGES_PER_UPLOAD = 200
#: Largest poses file, bytes (200 poses of 16 numbers take about 80 KB).
MAX_POSES_BYTES = 1 << 20
PlotName = Annotated[str, Path(max_length=64, description="residuals, coverage or consistency")]


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


Open = Annotated[dict[str, Any], Field(description="See the endpoint's summary")]


class SessionOut(BaseModel):
    session: Open


class SessionDetailOut(BaseModel):
    session: Open
    samples: list[Open]
    calibrations: list[Open]


class SamplesOut(Page[Open]):
    accepted: int
    rejected: int


class CalibrationOut(BaseModel):
    calibration: Open


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
    return {"session": svc.session_summary(row)}


@router.get(
    "/sessions", summary="This cell's calibration sessions, newest first", response_model=Page[Open]
)
async def read_calibration_sessions(
    _: ViewerUser, session: SessionDep, cell: CellDep, limit: Limit = 100, offset: Offset = 0
) -> dict[str, Any]:
    cell_id = await svc.cell_id_of(session, cell.name)
    rows = await svc.list_sessions(session, cell_id=cell_id, limit=limit, offset=offset)
    data = [svc.session_summary(r) for r in rows]
    return {"data": data, "count": await svc.count_sessions(session, cell_id=cell_id)}


def _sample_public(s: Any) -> dict[str, Any]:
    return {
        "index": s.index,
        "name": s.name,
        "accepted": s.accepted,
        "reason": s.reason,
        "corner_count": len(s.corners) if s.corners else 0,
        "joints": s.joints,
        "T_base_ee": s.T_base_ee,
        "created_at": s.created_at.isoformat(),
    }


@router.get(
    "/sessions/{session_id}",
    summary="One session with its samples and calibrations",
    response_model=SessionDetailOut,
)
async def read_calibration_session(_: ViewerUser, row: CalibrationSessionDep) -> dict[str, Any]:
    cals = sorted(row.calibrations, key=lambda c: c.id, reverse=True)
    return {
        "session": svc.session_summary(row),
        "samples": [_sample_public(s) for s in sorted(row.samples, key=lambda s: s.index)],
        "calibrations": [svc.calibration_public(c) for c in cals],
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
    data = [_sample_public(r) for r in rows]
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


@router.post(
    "/sessions/{session_id}/solve",
    summary="Solve the session as a job (202 with the job, or 200/422 with ?wait=true)",
    status_code=status.HTTP_202_ACCEPTED,
    response_class=JSONResponse,
    responses={
        200: {"model": JobOut, "description": "With ?wait=true: the finished job"},
        202: {"model": JobOut, "description": "The job, started"},
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


# -- calibrations -------------------------------------------------------------------------


@router.get(
    "/calibrations",
    summary="This cell's calibration history, newest first",
    response_model=Page[Open],
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
    data = [svc.calibration_public(r) for r in rows]
    total = await svc.count_history(session, cell_id=cell_id, kind=kind, session_id=session_id)
    return {"data": data, "count": total}


@router.get(
    "/active",
    summary="The active calibration of each kind in this cell",
    response_model=dict[str, Open | None],
)
async def read_active_calibrations(
    _: ViewerUser, session: SessionDep, cell: CellDep
) -> dict[str, Any]:
    cell_id = await svc.cell_id_of(session, cell.name)
    act = await svc.active_calibrations(session, cell_id)
    return {k.value: (svc.calibration_public(v) if v else None) for k, v in act.items()}


@router.get(
    "/calibrations/{calibration_id}", summary="One calibration", response_model=CalibrationOut
)
async def read_calibration(_: ViewerUser, cal: CalibrationDep) -> dict[str, Any]:
    return {"calibration": svc.calibration_public(cal)}


@router.get(
    "/calibrations/{calibration_id}/report",
    summary="Report: summary and plot links",
    response_model=Open,
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
    return {"calibration": svc.calibration_public(cal)}


# -- automatic calibration -----------------------------------------------------------------


class AutoIn(BaseModel):
    """An automatic calibration run (see ``backend.calibration.auto``)."""

    board: Literal["chessboard", "charuco"] = Field(
        "chessboard", description="Which board of the cell to use (simulated cell: the placed one)"
    )
    pattern: BoardIn | None = Field(
        None, description="The board's pattern; default: the simulated cell's board of that kind"
    )
    T_base_board: Matrix4 | None = Field(
        None,
        description="Where the board roughly is (4x4, metres); default: where the simulated "
        "cell's board was placed.  The first view measures it again.",
    )
    n_poses: Annotated[int, bounded_int(3, 60, "Views to plan")] = 25
    n_reserve: Annotated[int, bounded_int(0, 60, "Reserve views while criteria are unmet")] = 10
    activate: StrictBool = Field(False, description="Activate the solution")
    seed: Annotated[int, bounded_int(0, 2**32 - 1, "Seed of the view planner")] = 0
    speed: Speed = 0.6


@router.post(
    "/auto",
    status_code=status.HTTP_202_ACCEPTED,
    summary="Start an automatic calibration run (a motion job; 409 while the arm is busy)",
    response_model=JobOut,
)
async def create_calibration_auto(
    _: EngineerUser, db: DatabaseDep, cell: CellDep, sim: SimDep, body: AutoIn
) -> dict[str, Any]:
    from backend.calibration import auto

    cell.check_can_move()  # refuse before the planning work
    board, T = _auto_board(body, sim)
    world = cell.world if cell.world is not None else CollisionWorld()
    options = auto.AutoOptions(
        n_poses=body.n_poses,
        n_reserve=body.n_reserve,
        activate=body.activate,
        seed=body.seed,
        speed=body.speed,
    )
    run = await auto.prepare_auto_calibration(
        cell, board=board, T_base_board=T, options=options, world=world
    )

    async def body_(job: Job) -> dict[str, Any]:
        return await auto.run_auto_calibration(job, cell, db, run)

    job = cell.jobs.start(
        "auto_calibrate",
        body_,
        motion=True,
        params={**body.model_dump(), "plan": run.plan.as_dict()},
    )
    return {"job": job.public()}


def _auto_board(body: AutoIn, sim: Any) -> tuple[Board, np.ndarray]:
    """The board and its rough pose for ``body`` (from the simulated cell where not given)."""
    placed = None
    if sim is not None:
        placed = next((b for b in sim.boards() if b.kind == body.board), None)
    if body.pattern is not None:
        board = body.pattern.to_board()
    elif sim is not None:
        spec = next((s for s in sim.config.boards if s.kind == body.board), None)
        if spec is None:
            raise NotFound(f"this cell has no {body.board} board")
        from backend.calibration.auto import pattern_of_sim_board

        board = pattern_of_sim_board(spec)
    else:
        raise InvalidInput("pattern: give the board's pattern (no simulator)")
    if body.T_base_board is not None:
        return board, np.asarray(body.T_base_board, dtype=np.float64)
    if placed is None:
        raise InvalidInput(
            f"T_base_board: give where the board is; no {body.board} board is placed in the cell"
        )
    return board, np.asarray(placed.T_base_board, dtype=np.float64)
