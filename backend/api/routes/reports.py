"""Reports over the stored inspections: summary, time series, confusion,
streamed exports, the image storage and its pruning, and the 3D scene of one inspection.

Reading needs the viewer role, pruning the engineer role.  Filters (``from``, ``to``,
``cell``, ``model``, ``decision``, ``policy``) are validated by
:func:`backend.reports.make_filters`; the work is in :mod:`backend.reports`.
"""

from __future__ import annotations

from datetime import datetime
from typing import TYPE_CHECKING, Annotated, Any, Literal

from fastapi import APIRouter, Depends, Query
from fastapi.responses import Response, StreamingResponse
from pydantic import BaseModel, ConfigDict, Field

from backend.api.deps import (
    DatabaseDep,
    EngineerUser,
    RuntimeDep,
    SessionDep,
    SettingsDep,
    ViewerUser,
)
from backend.api.types import DbId, instant_query
from backend.reports import (
    ReportFilters,
    check_export,
    confusion,
    export_csv,
    export_jsonl,
    make_filters,
    prune,
    read_scene,
    storage_used,
    summary,
    timeseries,
)
from backend.reports.retention import MAX_PRUNE_BYTES, MAX_PRUNE_DAYS

__all__ = ["router"]

router = APIRouter(tags=["reports"])

if TYPE_CHECKING:  # the value a handler receives; FastAPI reads the Annotated form
    From = datetime | None
    To = datetime | None
else:
    From = instant_query("Inspections started at or after this time", alias="from")
    To = instant_query("Inspections started at or before this time", alias="to")

Decision = Literal["recognized", "unknown", "failed"]
Policy = Literal["naive", "top-only", "two-views", "best-next"]


def report_filters(
    start: From = None,
    end: To = None,
    cell: Annotated[str | None, Query(min_length=1, max_length=40, description="Cell name")] = None,
    model: Annotated[
        str | None, Query(min_length=1, max_length=64, description="Recognised model name")
    ] = None,
    decision: Decision | None = None,
    policy: Policy | None = None,
) -> ReportFilters:
    """The common filters of every report (422 naming a bad value)."""
    return make_filters(
        start=start, end=end, cell=cell, model=model, decision=decision, policy=policy
    )


FiltersDep = Annotated[ReportFilters, Depends(report_filters)]


class Percentiles(BaseModel):
    p50: float | None
    p95: float | None
    p99: float | None
    mean: float | None
    max: float | None


class StageStats(BaseModel):
    mean: float | None
    p50: float | None
    p95: float | None


class ScoreStats(BaseModel):
    p50: float | None
    p95: float | None
    min: float | None
    max: float | None


class Histogram(BaseModel):
    edges: list[float] = Field(description="11 bin edges over [0, 1]")
    counts: list[int] = Field(description="10 counts; bin i is [edge i, edge i+1)")


class ModelStats(BaseModel):
    model: str
    count: int
    score: ScoreStats
    hist: Histogram


class FiltersEcho(BaseModel):
    """The filters a report covers, as given (null: not filtered on)."""

    model_config = ConfigDict(populate_by_name=True)

    from_: str | None = Field(
        alias="from", serialization_alias="from", description="Started at or after, ISO time"
    )
    to: str | None = Field(description="Started at or before, ISO time")
    cell: str | None
    model: str | None
    decision: str | None
    policy: str | None


class SummaryPublic(BaseModel):
    """Totals, yield, cycle-time nearest-rank percentiles, the stage breakdown, per model scores."""

    count: int
    by_decision: dict[str, int]
    yield_: float | None = Field(alias="yield", serialization_alias="yield")
    cycle_s: Percentiles
    stages: dict[str, StageStats]
    views_mean: float | None
    per_model: list[ModelStats]
    first: str | None
    last: str | None
    filters: FiltersEcho

    model_config = ConfigDict(populate_by_name=True)


class BucketPublic(BaseModel):
    t: str = Field(description="Bucket start, UTC")
    count: int
    recognized: int
    unknown: int
    failed: int
    cycle_p50: float | None


class TimeseriesPublic(BaseModel):
    bucket: str
    data: list[BucketPublic]
    filters: FiltersEcho


class ConfusionPublic(BaseModel):
    labels: list[str] = Field(description="Decided labels: the models, then unknown, failed")
    truth: list[str] = Field(description="True catalogue names (simulator)")
    matrix: list[list[int]] = Field(description="Rows: truth; columns: labels")
    count: int
    filters: FiltersEcho


class StoragePublic(BaseModel):
    images: int = Field(description="Stored inspection images")
    bytes: int = Field(description="Bytes of the images and the 3D scene recordings")
    image_bytes: int
    scenes: int = Field(description="Stored 3D scene recordings")
    scene_bytes: int
    retention: Literal["all", "failures"]
    max_age_days: int | None
    max_bytes: int | None


class PruneIn(BaseModel):
    """What to prune now (absent: the settings' limits)."""

    model_config = ConfigDict(extra="forbid", strict=True)

    older_than_days: int | None = Field(None, ge=0, le=MAX_PRUNE_DAYS)
    max_bytes: int | None = Field(None, ge=0, le=MAX_PRUNE_BYTES)


class PruneOut(BaseModel):
    deleted_images: int
    freed_bytes: int
    deleted_scenes: int


@router.get("/reports/summary", response_model=SummaryPublic, response_model_by_alias=True,
            summary="Totals, yield, cycle-time percentiles, stages, score distributions")  # fmt: skip
async def read_summary(_: ViewerUser, session: SessionDep, f: FiltersDep) -> dict[str, Any]:
    """Exact over every matching inspection (from the report blocks): integer counts,
    nearest-rank percentiles (the stored value of rank ceil(p n / 100), never interpolated
    or binned), means of durations summed in 0.1 ms quanta; the same on SQLite and
    PostgreSQL."""
    return await summary(session, f)


@router.get("/reports/timeseries", response_model=TimeseriesPublic,
            summary="Counts per decision and median cycle time per minute, hour or day")  # fmt: skip
async def read_timeseries(
    _: ViewerUser,
    session: SessionDep,
    f: FiltersDep,
    bucket: Literal["minute", "hour", "day"] = "hour",
) -> dict[str, Any]:
    """Exact counts and the nearest-rank median cycle time of each UTC bucket, contiguous
    from the first to the last bucket with an inspection (at most 10,000 buckets)."""
    return await timeseries(session, f, bucket)


@router.get("/reports/confusion", response_model=ConfusionPublic,
            summary="Confusion matrix against the simulator's truth")  # fmt: skip
async def read_confusion(_: ViewerUser, session: SessionDep, f: FiltersDep) -> dict[str, Any]:
    """Exact counts of the matching inspections that carry a truth (simulator)."""
    return await confusion(session, f)


@router.get(
    "/reports/export.csv",
    response_class=StreamingResponse,
    summary="Every matching inspection as CSV (streamed, header first)",
    responses={
        200: {
            "content": {"text/csv": {}},
            "description": "A header line, then one line per inspection (a file download)",
        }
    },
)
async def export_inspections_csv(
    _: ViewerUser, db: DatabaseDep, f: FiltersDep
) -> StreamingResponse:
    await check_export(db, f)
    return StreamingResponse(
        export_csv(db, f),
        media_type="text/csv; charset=utf-8",
        headers={"Content-Disposition": 'attachment; filename="inspections.csv"'},
    )


@router.get(
    "/reports/export.jsonl",
    response_class=StreamingResponse,
    summary="Every matching inspection as JSON lines (streamed)",
    responses={
        200: {
            "content": {"application/x-ndjson": {}},
            "description": "One object per inspection, with the CSV export's columns as "
            "keys (a file download)",
        }
    },
)
async def export_inspections_jsonl(
    _: ViewerUser, db: DatabaseDep, f: FiltersDep
) -> StreamingResponse:
    await check_export(db, f)
    return StreamingResponse(
        export_jsonl(db, f),
        media_type="application/x-ndjson",
        headers={"Content-Disposition": 'attachment; filename="inspections.jsonl"'},
    )


@router.get("/reports/storage", response_model=StoragePublic,
            summary="Images and scene recordings stored, and the retention settings")  # fmt: skip
async def read_storage(_: ViewerUser, session: SessionDep, settings: SettingsDep) -> dict[str, Any]:
    used = await storage_used(session)
    return {
        **used,
        "retention": settings.image_retention,
        "max_age_days": settings.image_max_age_days,
        "max_bytes": settings.image_max_bytes,
    }


@router.post("/reports/storage/prune", response_model=PruneOut,
             summary="Delete the images of old inspections, by age or total size (engineer)")  # fmt: skip
async def prune_storage(
    _: EngineerUser, db: DatabaseDep, settings: SettingsDep, body: PruneIn
) -> dict[str, Any]:
    days = settings.image_max_age_days if body.older_than_days is None else body.older_than_days
    cap = settings.image_max_bytes if body.max_bytes is None else body.max_bytes
    res = await prune(db, older_than_days=days, max_bytes=cap)
    return res.public()


@router.get(
    "/inspections/{inspection_id}/scene",
    response_class=Response,
    summary="The 3D scene recorded during the inspection (viser scene serializer)",
    responses={
        200: {
            "content": {"application/octet-stream": {}},
            "description": "The recording, as viser's scene serializer writes it",
        }
    },
)
async def read_inspection_scene(
    _: ViewerUser, rt: RuntimeDep, session: SessionDep, inspection_id: DbId
) -> Response:
    """The recording of one of this cell's inspections (404 for another cell's, as its row)."""
    data = await read_scene(session, inspection_id, rt.cell_id)
    return Response(data, media_type="application/octet-stream")
