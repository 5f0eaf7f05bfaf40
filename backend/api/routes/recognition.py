"""Recognition: recognising uploaded images, the global score threshold and how it was
chosen (kept up to date after every change of the trained views).  The negative images the
automatic threshold is chosen against: :mod:`backend.api.routes.negatives`.

Recognising needs the viewer role; storing the results as inspection rows
(``store=true``) the operator role; setting the threshold the engineer role.
"""

from __future__ import annotations

import json
import time
from typing import Annotated, Any, Literal

from fastapi import APIRouter, File, Form, UploadFile
from pydantic import BaseModel, Field

from backend import audit
from backend.api.deps import (
    EngineerUser,
    RuntimeDep,
    SessionDep,
    SettingsDep,
    ViewerUser,
    read_through,
)
from backend.api.errors import ApiError
from backend.api.types import bounded_float
from backend.api.uploads import read_capped
from backend.api.work import HeavyWorkDep
from backend.db.models import RecognitionSettings, Role
from backend.db.session import changed
from backend.db.types import utcnow
from backend.inspection.results import store_all
from backend.recognition import images as im
from backend.recognition.public import RecognitionSettingsPublic
from backend.recognition.recognise import Region, inspection_record, recognise_upload
from backend.recognition.thresholds import (
    back_to_automatic,
    current_choice,
    latest_settings,
    settings_audit_value,
)
from vision.errors import InvalidInput

#: Database integer keys are 32-bit signed on PostgreSQL.
DB_ID_MAX = 2**31 - 1
#: What the thresholds in force are read from (the read cache drops them on a write).
CHOICE_TABLES = ("recognition_settings", "object_models")

router = APIRouter(prefix="/recognition", tags=["recognition"])


class RecognitionSettingsIn(BaseModel):
    global_threshold: (
        Annotated[
            float,
            bounded_float(0.0, 1.0, "Score above which a model is reported; null: automatic again"),
        ]
        | None
    )
    note: str = Field("", max_length=500)
    reason: str | None = Field(
        None, max_length=audit.MAX_REASON_LENGTH, description="Why (kept in the audit trail)"
    )


@router.get(
    "/settings",
    summary="The recognition settings in force",
    response_model=RecognitionSettingsPublic,
)
async def read_recognition_settings(
    _: ViewerUser, session: SessionDep
) -> RecognitionSettingsPublic:
    return RecognitionSettingsPublic.of(await latest_settings(session))


@router.put(
    "/settings",
    summary="Set the global threshold by hand, or null to hand it back to the automatic rule (engineer)",
    response_model=RecognitionSettingsPublic,
)
async def update_recognition_settings(
    user: EngineerUser, session: SessionDep, body: RecognitionSettingsIn
) -> RecognitionSettingsPublic:
    """A number sets the threshold by hand (``chosen_by="manual"``), which the automatic
    rule then never overwrites; ``null`` ends that: the newest automatic choice (or the
    default) is in force again and later teaches recompute it.  Each change is audited
    (``set`` / ``automatic``); ``null`` while already automatic changes nothing."""
    if body.global_threshold is None:
        before, after = await back_to_automatic(session)
        if after is not None and after is not before:
            _audit_threshold(session, user, body, "automatic", before, after)
        return RecognitionSettingsPublic.of(after)
    before = await latest_settings(session)
    row = RecognitionSettings(
        global_threshold=body.global_threshold,
        chosen_by="manual",
        detail={"by": user.name, "note": body.note},
    )
    session.add(row)
    changed(session, "recognition_settings")
    await session.flush()
    _audit_threshold(session, user, body, "set", before, row)
    return RecognitionSettingsPublic.of(row)


def _audit_threshold(
    session: Any,
    user: Any,
    body: RecognitionSettingsIn,
    action: str,
    before: RecognitionSettings | None,
    after: RecognitionSettings,
) -> None:
    audit.record(
        session,
        actor=audit.Actor.of(user),
        kind="threshold",
        entity_id="global",
        action=action,
        old=None if before is None else settings_audit_value(before),
        new=settings_audit_value(after),
        reason=body.reason or body.note or None,
    )


# -- recognising uploaded images ---------------------------------------------------------


class ModelScoreOut(BaseModel):
    model: str
    score: float = Field(description="Registration score in [0, 1]")
    threshold: float = Field(description="The bar this model must pass at the viewpoint")
    passed: bool


class ImagePoseOut(BaseModel):
    x_px: float = Field(description="Image column of the matched view's centre, pixels")
    y_px: float = Field(description="Image row of the matched view's centre, pixels")
    angle_rad: float = Field(description="Turn from the trained view to the image, radians")
    scale: float = Field(description="Size in the image over size in the trained view")


class ImageResultOut(BaseModel):
    name: str
    width: int
    height: int
    viewpoint: int
    decision: str = Field(description="recognized, ambiguous or unknown")
    model: str | None
    best_model: str | None
    score: float
    threshold: float
    scores: list[ModelScoreOut] = Field(description="Every model, best first")
    contenders: list[str]
    view_id: int | None = Field(description="The trained view that matched best")
    outline_px: list[list[float]] = Field(description="Matched view's outline in the image")
    pose: ImagePoseOut | None
    n_features: int
    durations: dict[str, float] = Field(
        description="Seconds per stage: decode, features, retrieve, verify, decide"
    )
    inspection_id: int | None = Field(None, description="The stored row (store=true)")


class AppliedThresholdOut(BaseModel):
    """The thresholds applied to a request's images and how they were chosen."""

    chosen_by: str = Field(description="default, auto or manual (the settings in force)")
    global_threshold: float = Field(description="The global threshold at the viewpoint")
    rule: str = Field(description="The rule that chose the thresholds")


class RecogniseOut(BaseModel):
    data: list[ImageResultOut]
    count: int
    threshold: AppliedThresholdOut
    durations: dict[str, float] = Field(description="Seconds of the request: total, store")


def _region(text: str | None) -> Region | None:
    """``x,y,width,height`` in pixels (or a JSON list of the four), or None."""
    if text is None or not text.strip():
        return None
    raw = text.strip()
    try:
        values = json.loads(raw) if raw.startswith("[") else [int(v) for v in raw.split(",")]
    except (ValueError, json.JSONDecodeError):
        raise InvalidInput(
            f"region must be x,y,width,height in pixels, got {text[:80]!r}"
        ) from None
    if not isinstance(values, list) or len(values) != 4:
        raise InvalidInput(f"region must be four numbers x,y,width,height, got {text[:80]!r}")
    if any(isinstance(v, bool) or not isinstance(v, int) for v in values):
        raise InvalidInput(f"region must be four integers, got {text[:80]!r}")
    return Region(*values)


@router.post(
    "/recognise",
    summary="Recognise uploaded images against every trained model (viewer; store=true: operator)",
    response_model=RecogniseOut,
)
async def recognise_images(
    user: ViewerUser,
    runtime: RuntimeDep,
    settings: SettingsDep,
    work: HeavyWorkDep,
    images: Annotated[list[UploadFile], File(description="PNG or JPEG images")],
    masks: Annotated[
        list[UploadFile] | None,
        File(description="Optional masks, one per image (white = where to look)"),
    ] = None,
    viewpoint: Annotated[
        int, Form(ge=1, le=3, description="Trained viewpoint to compare with: 1 top, 2, 3 sides")
    ] = 1,
    region: Annotated[
        str | None, Form(max_length=64, description="x,y,width,height in pixels to look in")
    ] = None,
    store: Annotated[
        bool, Form(description="Store each result as an inspection (source upload; operator)")
    ] = False,
) -> dict[str, Any]:
    """For each image: the decision, the model, every model's score against its threshold,
    the outline of the matched view and the 2D pose in the image, and the time per stage.
    Images are checked (count, bytes, pixels from their headers) before any is decoded;
    decoding and recognition run in the runtime's heavy-work pool, within the request's
    pixel budget (:mod:`backend.heavy`); a client that leaves drops what is still queued."""
    t0 = time.perf_counter()
    if store and Role[user.role] < Role.operator:
        raise ApiError(
            403, "forbidden",
            f"storing results needs the operator role; user {user.name!r} is {user.role}",
        )  # fmt: skip
    n = len(images)
    if n > settings.recognise_max_images:
        raise InvalidInput(f"at most {settings.recognise_max_images} images at once, got {n}")
    masks = masks or []
    if masks and len(masks) != n:
        raise InvalidInput(f"give one mask per image ({n}) or none, got {len(masks)}")
    box = _region(region)
    names = [f.filename or f"image {k}" for k, f in enumerate(images)]
    datas = [await read_capped(f, im.MAX_IMAGE_BYTES) for f in images]
    mask_datas = [await read_capped(m, im.MAX_IMAGE_BYTES) for m in masks]
    heads = [im.check_header(d, name=nm) for d, nm in zip(datas, names, strict=True)]
    for k, m in enumerate(mask_datas):
        head = im.check_header(m, name=f"mask of {names[k]}")
        if (head.width, head.height) != (heads[k].width, heads[k].height):
            raise InvalidInput(
                f"the mask of {names[k]!r} is {head.width} x {head.height} px, the image "
                f"{heads[k].width} x {heads[k].height} px"
            )
    db = runtime.database
    live = runtime.live_index

    async def read_choice(session: Any) -> tuple[Any, str]:
        row = await latest_settings(session)
        return await current_choice(session), "default" if row is None else row.chosen_by

    # The thresholds in force change with a settings row or a model's own threshold: read
    # through the cache, which a commit to either table clears.
    choice, chosen_by = await read_through(
        runtime.read_cache, db, user, ("recognise-thresholds",), tables=CHOICE_TABLES,
        read=read_choice,
    )  # fmt: skip
    started = utcnow()

    async with work.job() as job:
        # The whole request's pixels are counted before the first decode (413 past the
        # budget, or an image too large to extract features from).
        for k, h in enumerate(heads):
            job.take_pixels(h.width, h.height, name=names[k], analysed=True)
            if mask_datas:
                job.take_pixels(h.width, h.height, name=f"mask of {names[k]}")
        results = []
        for k in range(n):
            mask = mask_datas[k] if mask_datas else None
            got = await job.run(recognise_upload, live, datas[k], name=names[k], viewpoint=viewpoint,
                                choice=choice, mask_data=mask, region=box, annotate=store)  # fmt: skip
            results.append(got)
    out = [r.public() for r, _jpeg in results]
    t_store = 0.0
    if store:
        t1 = time.perf_counter()
        finished = utcnow()
        ids = {m.name: m.id for m in live.models().values()}
        records = [
            inspection_record(r, jpeg, started_at=started, finished_at=finished, model_ids=ids)
            for r, jpeg in results
            if jpeg is not None
        ]
        stored = await store_all(db, runtime.cell_id, records, retention=settings.image_retention)
        for o, iid in zip(out, stored, strict=True):
            o["inspection_id"] = iid
        t_store = time.perf_counter() - t1
    return {
        "data": out,
        "count": len(out),
        "threshold": {
            "chosen_by": chosen_by,
            "global_threshold": choice.at(viewpoint).threshold,
            "rule": choice.rule,
        },
        "durations": {"total": time.perf_counter() - t0, "store": t_store},
    }


# -- the automatic threshold ----------------------------------------------------------------


class ThresholdStatusOut(BaseModel):
    follow: bool = Field(description="Recomputed after every change of the views (setting)")
    state: Literal["idle", "waiting", "running"] = Field(
        description="idle, waiting (changes seen) or running"
    )
    job: str | None
    runs: int = Field(description="Recomputations finished")
    superseded: int = Field(description="Recomputations stopped by a change while they ran")
    last: dict[str, Any] | None = Field(description="The last recomputation's outcome")
    settings: RecognitionSettingsPublic


@router.get(
    "/threshold",
    summary="The automatic threshold: its state, the last recomputation and the settings in force",
    response_model=ThresholdStatusOut,
)
async def read_threshold_status(
    _: ViewerUser, runtime: RuntimeDep, session: SessionDep
) -> dict[str, Any]:
    keeper = runtime.threshold_keeper
    state = (
        keeper.status()
        if keeper is not None
        else {"state": "idle", "job": None, "runs": 0, "superseded": 0, "last": None}
    )
    return {
        "follow": keeper is not None,
        "state": state["state"],
        "job": state["job"],
        "runs": state["runs"],
        "superseded": state["superseded"],
        "last": state["last"],
        "settings": RecognitionSettingsPublic.of(await latest_settings(session)),
    }
