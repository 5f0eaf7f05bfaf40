"""Recognition settings: the global score threshold and how it was chosen."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter
from pydantic import BaseModel, Field

from backend import audit
from backend.api.deps import EngineerUser, SessionDep, ViewerUser
from backend.api.types import bounded_float
from backend.db.models import RecognitionSettings
from backend.recognition.thresholds import (
    DEFAULT_THRESHOLD,
    back_to_automatic,
    latest_settings,
    settings_audit_value,
)

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


class RecognitionSettingsOut(BaseModel):
    global_threshold: float
    chosen_by: str
    detail: dict[str, Any]
    created_at: str | None


def _public(row: RecognitionSettings | None) -> dict[str, Any]:
    if row is None:
        return {
            "global_threshold": DEFAULT_THRESHOLD,
            "chosen_by": "default",
            "detail": {},
            "created_at": None,
        }
    return {
        "global_threshold": row.global_threshold,
        "chosen_by": row.chosen_by,
        "detail": row.detail,
        "created_at": row.created_at.isoformat(),
    }


@router.get(
    "/settings",
    summary="The recognition settings in force",
    response_model=RecognitionSettingsOut,
)
async def read_recognition_settings(_: ViewerUser, session: SessionDep) -> dict[str, Any]:
    return _public(await latest_settings(session))


@router.put(
    "/settings",
    summary="Set the global threshold by hand, or null to hand it back to the automatic rule (engineer)",
    response_model=RecognitionSettingsOut,
)
async def update_recognition_settings(
    user: EngineerUser, session: SessionDep, body: RecognitionSettingsIn
) -> dict[str, Any]:
    """A number sets the threshold by hand (``chosen_by="manual"``), which the automatic
    rule then never overwrites; ``null`` ends that: the newest automatic choice (or the
    default) is in force again and later teaches recompute it.  Each change is audited
    (``set`` / ``automatic``); ``null`` while already automatic changes nothing."""
    if body.global_threshold is None:
        before, after = await back_to_automatic(session)
        if after is not None and after is not before:
            _audit_threshold(session, user, body, "automatic", before, after)
        return _public(after)
    before = await latest_settings(session)
    row = RecognitionSettings(
        global_threshold=body.global_threshold,
        chosen_by="manual",
        detail={"by": user.name, "note": body.note},
    )
    session.add(row)
    await session.flush()
    _audit_threshold(session, user, body, "set", before, row)
    return _public(row)


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
