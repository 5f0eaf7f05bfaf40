"""Request and answer shapes shared by several routers, and the error body.

Inputs use the bounded types of :mod:`backend.api.types`; answers are Public schemas so that
OpenAPI documents them.  Lists are :class:`Page` (``{"data": [...], "count": total}``).
"""

from __future__ import annotations

import math
from typing import Any, Generic, TypeVar

from pydantic import BaseModel, ConfigDict, Field, model_validator

from backend.api.types import ApproachComponent, JointList, Metres
from backend.publictypes import IsoTime
from robot.kinematics.analytic import UNIT_TOL

__all__ = [
    "BODY_ERROR_RESPONSES",
    "ERROR_RESPONSES",
    "ErrorOut",
    "IsoTime",
    "JobOut",
    "JobPublic",
    "JointsIn",
    "Page",
    "PoseIn",
    "PoseOut",
    "RobotStateOut",
    "page",
]

T = TypeVar("T")


class ErrorOut(BaseModel):
    """The body of every error answer."""

    error: str = Field(description="Stable code, e.g. not_found, validation_error, robot_busy")
    detail: str = Field(description="What went wrong, quoting the bad value")


#: The documented error answers of every operation (added to the router).
ERROR_RESPONSES: dict[int | str, dict[str, Any]] = {
    code: {"model": ErrorOut, "description": text}
    for code, text in (
        (400, "The request itself is malformed (an unreadable line, header or body)"),
        (401, "Missing, invalid or revoked token"),
        (403, "The token's role is too low"),
        (404, "No such resource"),
        (409, "Conflicts with the cell's state (arm busy, E-STOP, name taken)"),
        (422, "A value is out of range, malformed or of the wrong type"),
        (500, "A bug in VisionCell (logged)"),
        (503, "The cell, driver or camera is not available"),
    )
}


#: The documented error answers of every operation that takes a body (added per route).
BODY_ERROR_RESPONSES: dict[int | str, dict[str, Any]] = {
    415: {
        "model": ErrorOut,
        "description": "The body's media type or an uploaded file's format is not accepted",
    },
}


class Page(BaseModel, Generic[T]):
    """One page of a list; ``count`` is the total number of items, not the page size."""

    data: list[T]
    count: int = Field(ge=0, description="Total number of items (all pages)")


def page(items: list[Any], *, limit: int, offset: int) -> dict[str, Any]:
    """The ``{"data", "count"}`` answer of an in-memory list."""
    return {"data": items[offset : offset + limit], "count": len(items)}


class PoseIn(BaseModel):
    """The chapter's pose (eq. 20): flange position in metres and approach direction
    ``(u, w) = (cos phi, sin phi)`` with ``phi`` the approach angle from the horizontal."""

    x: Metres
    y: Metres
    z: Metres
    u: ApproachComponent
    w: ApproachComponent

    @model_validator(mode="after")
    def _unit(self) -> PoseIn:
        n = math.hypot(self.u, self.w)
        if abs(n - 1.0) > UNIT_TOL:
            raise ValueError(
                f"(u, w) must be a unit vector (u^2 + w^2 = 1 within {UNIT_TOL:g}), got "
                f"({self.u!r}, {self.w!r}) of length {n:.9g}"
            )
        return self

    def as_tuple(self) -> tuple[float, float, float, float, float]:
        return (self.x, self.y, self.z, self.u, self.w)


class PoseOut(BaseModel):
    """The chapter's pose of the flange (eq. 20)."""

    x: float
    y: float
    z: float
    u: float
    w: float


class JointsIn(BaseModel):
    """Joint values q1..q5 in radians."""

    joints: JointList


class JobPublic(BaseModel):
    """A job: a move, a solve, an automatic calibration."""

    id: str
    kind: str
    state: str = Field(
        description="running, done, failed, cancelled, or interrupted (the process ended "
        "while it ran)"
    )
    progress: float = Field(description="0 .. 1")
    message: str
    params: dict[str, Any] = Field(
        description="What the job was asked to do; open because each kind of job takes its "
        "own parameters (a move's target, a solve's options, a teach's rounds)"
    )
    created_at: str
    finished_at: str | None
    result: dict[str, Any] | None = Field(
        description="What a finished job produced (None until then); open because each kind "
        "of job answers its own result (a move's final state, a solve's calibration id)"
    )
    error: ErrorOut | None = Field(description="Why the job failed (None unless it did)")


class JobOut(BaseModel):
    job: JobPublic


class RobotStateOut(BaseModel):
    """The latest joint state of the arm."""

    model_config = ConfigDict(extra="allow")

    q: list[float]
    qd: list[float]
    stamp_s: float
    connected: bool
    moving: bool
    estopped: bool
    fault: str
