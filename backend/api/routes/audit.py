"""The audit trail, read only (engineer role): no endpoint creates, edits or deletes rows."""

from __future__ import annotations

from datetime import datetime
from typing import TYPE_CHECKING, Annotated, Any, Literal

from fastapi import APIRouter, Query
from pydantic import BaseModel, ConfigDict, Field

from backend import audit
from backend.api.deps import EngineerUser, SessionDep
from backend.api.schemas import Page
from backend.api.types import Limit, Offset, instant_query

router = APIRouter(prefix="/audit", tags=["audit"])

if TYPE_CHECKING:  # the value a handler receives; FastAPI reads the Annotated form
    Since = datetime | None
    Until = datetime | None
else:
    Since = instant_query("From this time on, inclusive")
    Until = instant_query("Before this time, exclusive")

Kind = Literal[
    "threshold", "model", "view", "negative", "calibration", "user", "token", "estop", "recipe"
]


class AuditPublic(BaseModel):
    """An audit row as the API shows it (read from the row)."""

    model_config = ConfigDict(from_attributes=True)

    id: int
    at: datetime
    actor: str
    actor_role: str
    kind: str
    entity_id: str
    action: str
    old: dict[str, Any] | None = Field(
        description="The entity's audited values before (null: it did not exist); open "
        "because each kind of entity (model, recipe, threshold, user ...) has its own"
    )
    new: dict[str, Any] | None = Field(
        description="Its audited values after (null: it was deleted); open as old is"
    )
    reason: str


@router.get(
    "", summary="The audit trail, newest first (engineer)", response_model=Page[AuditPublic]
)
async def read_audit(
    _: EngineerUser,
    session: SessionDep,
    kind: Annotated[Kind | None, Query(description="What was changed")] = None,
    entity_id: Annotated[
        str | None, Query(min_length=1, max_length=64, description="The changed row's id")
    ] = None,
    actor: Annotated[
        str | None, Query(min_length=1, max_length=64, description="User name, cli or system")
    ] = None,
    since: Since = None,
    until: Until = None,
    limit: Limit = 100,
    offset: Offset = 0,
) -> Page[AuditPublic]:
    rows, total = await audit.query(
        session,
        kind=kind,
        entity_id=entity_id,
        actor=actor,
        since=since,
        until=until,
        limit=limit,
        offset=offset,
    )
    return Page[AuditPublic](data=[AuditPublic.model_validate(r) for r in rows], count=total)
