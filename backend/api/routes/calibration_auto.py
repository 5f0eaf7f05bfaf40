"""Automatic calibration (under ``/api/calibration``): start a run, a motion job.

Starting one needs the engineer role.  The work itself is in
:mod:`backend.calibration.auto`.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

import numpy as np
from fastapi import APIRouter, status
from pydantic import BaseModel, Field

from backend.api.deps import CellDep, DatabaseDep, EngineerUser, SimDep
from backend.api.routes.calibration import BoardIn
from backend.api.schemas import JobOut
from backend.api.types import Matrix4, Speed, StrictBool, bounded_int
from backend.jobs import Job
from robot.collision import CollisionWorld
from vision.calibration import Board
from vision.errors import InvalidInput, NotFound

__all__ = ["router"]

router = APIRouter(prefix="/calibration", tags=["calibration"])


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
