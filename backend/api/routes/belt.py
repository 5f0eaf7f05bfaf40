"""The cell's belt: its state (viewer) and starting or stopping it (operator).

The belt an inspection run waits on is the operator's to start: these endpoints reach it
through the cell's conveyor driver (the simulator's belt, or a plant's conveyor behind the
same protocol), never the simulator's truth.  A cell without a conveyor it can read answers
``{"belt": null}`` and 409 ``conflict`` to a start.
"""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter
from pydantic import BaseModel, ConfigDict, Field

from backend.api.deps import OperatorUser, RuntimeDep, ViewerUser
from backend.inspection import waiting
from backend.runtime import CellRuntime
from vision.errors import Conflict

__all__ = ["router"]

router = APIRouter(prefix="/belt", tags=["belt"])


class BeltIn(BaseModel):
    """Start or stop the belt."""

    model_config = ConfigDict(extra="forbid", strict=True)

    running: bool = Field(description="true: start the belt; false: stop it")


class BeltPublic(BaseModel):
    """What the operator and a waiting run need to know about the belt."""

    running: bool = Field(description="It runs (commanded to, and not held by the E-STOP)")
    halted: bool = Field(description="The emergency stop holds it")
    mode: str = Field(description="continuous, or index: it stops each object at the station")
    speed_m_s: float = Field(description="Its speed when it runs, m/s")
    holding: bool = Field(description="Index mode: it holds an object at the station now")
    travel_m: float = Field(description="Its encoder: metres travelled since start-up")
    objects: int | None = Field(description="Objects on it (null: it cannot count them)")


class BeltOut(BaseModel):
    belt: BeltPublic | None = Field(description="null when the cell has no conveyor it can read")
    summary: str = Field(description="One line for the operator")


def _answer(rt: CellRuntime) -> dict[str, Any]:
    st = waiting.belt_status(rt)
    return {"belt": None if st is None else st.as_dict(), "summary": waiting.describe(st)}


@router.get("", summary="The belt's state (viewer)", response_model=BeltOut)
async def read_belt(_: ViewerUser, rt: RuntimeDep) -> dict[str, Any]:
    return _answer(rt)


@router.post(
    "",
    summary="Start or stop the belt (operator; refused while the emergency stop holds it)",
    response_model=BeltOut,
)
async def update_belt(_: OperatorUser, rt: RuntimeDep, body: BeltIn) -> dict[str, Any]:
    conveyor = waiting.require_conveyor(rt)
    if body.running and (rt.cell.estopped or conveyor.halted):
        raise Conflict("the emergency stop is active: reset the cell before starting the belt")
    await conveyor.set_running(body.running)
    return _answer(rt)
