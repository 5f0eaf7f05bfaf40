"""The arm: state, joint moves, stop, emergency stop, reset, home."""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal

from fastapi import APIRouter, Query, status
from fastapi.responses import JSONResponse
from pydantic import BaseModel, Field, field_validator, model_validator

from backend.api.deps import CellDep, OperatorUser, ViewerUser
from backend.api.schemas import PoseIn, check_joint_list
from backend.jobs import Job

router = APIRouter(prefix="/robot", tags=["robot"])


class MoveIn(BaseModel):
    """A joint target, or a Cartesian target in the chapter's pose form (solved by IK).

    Exactly one of ``joints`` and ``pose`` must be given.
    """

    joints: list[float] | None = Field(
        None, description="q1..q5 in radians", examples=[[0.0, 1.5708, -1.5708, 0.0, 0.0]]
    )
    pose: PoseIn | None = Field(
        None, description="Flange target (x, y, z in metres, u = cos phi, w = sin phi)"
    )
    roll: float = Field(0.0, description="With pose: rotation about the approach axis, radians")
    path: Literal["joint", "line"] = Field(
        "joint", description="With pose: joint-space move or straight line"
    )
    speed: float | None = Field(
        None, gt=0.0, le=1.0, description="0 < speed <= 1 (default: the cell's speed)"
    )

    @field_validator("joints")
    @classmethod
    def _five_finite(cls, v: list[float] | None) -> list[float] | None:
        return None if v is None else check_joint_list(v)

    @field_validator("roll")
    @classmethod
    def _finite_roll(cls, v: float) -> float:
        if not math.isfinite(v):
            raise ValueError(f"roll must be finite, got {v!r}")
        return v

    @model_validator(mode="after")
    def _one_target(self) -> MoveIn:
        if (self.joints is None) == (self.pose is None):
            raise ValueError("give exactly one of 'joints' and 'pose'")
        return self


class SpeedIn(BaseModel):
    speed: float | None = Field(None, gt=0.0, le=1.0)


async def _answer(cell: Any, job: Job, wait: bool) -> JSONResponse:
    if wait:
        await cell.jobs.wait(job)
        return JSONResponse({"job": job.public()}, status_code=status.HTTP_200_OK)
    return JSONResponse({"job": job.public()}, status_code=status.HTTP_202_ACCEPTED)


WaitQuery = Annotated[bool, Query(description="Answer when the move has ended instead of at once")]


@router.get("/state", summary="Latest joint state")
async def read_state(_: ViewerUser, cell: CellDep) -> dict[str, Any]:
    return {"state": cell.driver.state.as_dict(), "speed": cell.speed, "driver": cell.driver.name}


@router.post(
    "/move", summary="Move to a joint or Cartesian target (202 with a job, or 200 with ?wait=true)"
)
async def create_move(
    _: OperatorUser, cell: CellDep, body: MoveIn, wait: WaitQuery = False
) -> JSONResponse:
    if body.pose is not None:
        job = cell.move_pose(body.pose.as_tuple(), roll=body.roll, speed=body.speed, path=body.path)
    else:
        job = cell.move_joints(body.joints, speed=body.speed)
    return await _answer(cell, job, wait)


@router.post("/home", summary="Move to the home configuration")
async def create_home(
    _: OperatorUser, cell: CellDep, body: SpeedIn | None = None, wait: WaitQuery = False
) -> JSONResponse:
    job = cell.home(speed=body.speed if body else None)
    return await _answer(cell, job, wait)


@router.post("/stop", summary="Controlled stop of the current move")
async def create_stop(_: OperatorUser, cell: CellDep) -> dict[str, Any]:
    await cell.stop_motion()
    return {"state": cell.driver.state.as_dict()}


@router.post("/estop", summary="Emergency stop (any signed-in user may press it)")
async def create_estop(_: ViewerUser, cell: CellDep) -> dict[str, Any]:
    await cell.estop()
    return {"state": cell.driver.state.as_dict()}


@router.post("/reset", summary="Clear an emergency stop")
async def create_reset(_: OperatorUser, cell: CellDep) -> dict[str, Any]:
    await cell.reset()
    return {"state": cell.driver.state.as_dict()}


@router.put("/speed", summary="Default speed for moves, 0 < speed <= 1")
async def update_speed(_: OperatorUser, cell: CellDep, body: SpeedIn) -> dict[str, Any]:
    if body.speed is not None:
        cell.speed = body.speed
    return {"speed": cell.speed}
