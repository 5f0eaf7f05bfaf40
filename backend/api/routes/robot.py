"""The arm: state, joint moves, stop, emergency stop, reset, home."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import APIRouter, Query, status
from fastapi.responses import JSONResponse
from pydantic import BaseModel, Field, model_validator

from backend.api.deps import CellDep, EStopUser, OperatorUser, ViewerUser
from backend.api.fastpath import FastRequest, Fresh
from backend.api.schemas import JobOut, PoseIn, RobotStateOut
from backend.api.types import JointList, RollRad, Speed
from backend.jobs import Job

router = APIRouter(prefix="/robot", tags=["robot"])


class MoveIn(BaseModel):
    """A joint target, or a Cartesian target in the chapter's pose form (solved by IK).

    Exactly one of ``joints`` and ``pose`` must be given.
    """

    joints: JointList | None = None
    pose: PoseIn | None = Field(
        None, description="Flange target (x, y, z in metres, u = cos phi, w = sin phi)"
    )
    roll: RollRad = 0.0
    path: Literal["joint", "line"] = Field(
        "joint", description="With pose: joint-space move or straight line"
    )
    speed: Speed | None = Field(None, description="Speed fraction (default: the cell's speed)")

    @model_validator(mode="after")
    def _one_target(self) -> MoveIn:
        if (self.joints is None) == (self.pose is None):
            raise ValueError("give exactly one of 'joints' and 'pose'")
        return self


class SpeedIn(BaseModel):
    speed: Speed | None = None


class StateOut(BaseModel):
    state: RobotStateOut
    speed: float = Field(description="The cell's default speed fraction")
    driver: str


class StateOnlyOut(BaseModel):
    state: RobotStateOut


class SpeedOut(BaseModel):
    speed: float


async def _answer(cell: Any, job: Job, wait: bool) -> JSONResponse:
    if wait:
        await cell.jobs.wait(job)
        return JSONResponse({"job": job.public()}, status_code=status.HTTP_200_OK)
    return JSONResponse({"job": job.public()}, status_code=status.HTTP_202_ACCEPTED)


WaitQuery = Annotated[bool, Query(description="Answer when the move has ended instead of at once")]
_JOB_ANSWERS: dict[int | str, dict[str, Any]] = {
    200: {"model": JobOut, "description": "With ?wait=true: the finished job"},
    202: {"model": JobOut, "description": "The job, started"},
}


def state_answer(cell: Any) -> dict[str, Any]:
    """The arm's state answer now."""
    return {"state": cell.driver.state.as_dict(), "speed": cell.speed, "driver": cell.driver.name}


@router.get("/state", summary="Latest joint state", response_model=StateOut)
async def read_state(_: ViewerUser, cell: CellDep) -> dict[str, Any]:
    return state_answer(cell)


async def fast_read_state(req: FastRequest) -> Fresh | None:
    """:func:`read_state` (kept while the state is equal: at rest)."""
    return Fresh.of_content(state_answer(req.runtime.cell))


@router.post(
    "/move",
    summary="Move to a joint or Cartesian target (202 with a job, or 200 with ?wait=true)",
    status_code=status.HTTP_202_ACCEPTED,
    response_class=JSONResponse,
    responses=_JOB_ANSWERS,
)
async def create_move(
    _: OperatorUser, cell: CellDep, body: MoveIn, wait: WaitQuery = False
) -> JSONResponse:
    if body.pose is not None:
        job = cell.move_pose(body.pose.as_tuple(), roll=body.roll, speed=body.speed, path=body.path)
    elif body.joints is not None:
        job = cell.move_joints(body.joints, speed=body.speed)
    else:  # MoveIn's validator already refuses this
        raise ValueError("give exactly one of 'joints' and 'pose'")
    return await _answer(cell, job, wait)


@router.post(
    "/home",
    summary="Move to the home configuration",
    status_code=status.HTTP_202_ACCEPTED,
    response_class=JSONResponse,
    responses=_JOB_ANSWERS,
)
async def create_home(
    _: OperatorUser, cell: CellDep, body: SpeedIn | None = None, wait: WaitQuery = False
) -> JSONResponse:
    job = cell.home(speed=body.speed if body else None)
    return await _answer(cell, job, wait)


@router.post("/stop", summary="Controlled stop of the current move", response_model=StateOnlyOut)
async def create_stop(_: OperatorUser, cell: CellDep) -> dict[str, Any]:
    await cell.stop_motion()
    return {"state": cell.driver.state.as_dict()}


@router.post(
    "/estop",
    summary="Emergency stop (any signed-in user may press it)",
    description="Latches the arm and the conveyors and answers at once: the token is "
    "checked from memory (one this cell has seen signed in within the hour), never "
    "throttled when valid, and nothing waits for the database (the audit record is "
    "written afterwards).",
    response_model=StateOnlyOut,
)
async def create_estop(user: EStopUser, cell: CellDep) -> dict[str, Any]:
    await cell.estop(by=user.name, role=user.role, source="rest")
    return {"state": cell.driver.state.as_dict()}


@router.post("/reset", summary="Clear an emergency stop", response_model=StateOnlyOut)
async def create_reset(user: OperatorUser, cell: CellDep) -> dict[str, Any]:
    await cell.reset(by=user.name, role=user.role, source="rest")
    return {"state": cell.driver.state.as_dict()}


@router.put(
    "/speed", summary="Default speed for moves, 0.01 <= speed <= 1", response_model=SpeedOut
)
async def update_speed(_: OperatorUser, cell: CellDep, body: SpeedIn) -> dict[str, Any]:
    if body.speed is not None:
        cell.speed = body.speed
    return {"speed": cell.speed}
