"""Forward and inverse kinematics of the arm (chapter eq. 20), for tools and the console."""

from __future__ import annotations

import math
from typing import Any

from fastapi import APIRouter
from pydantic import BaseModel, Field, field_validator

from backend.api.deps import ViewerUser
from backend.api.schemas import JointsIn, PoseIn
from robot.kinematics import T_base_ee, fk, ik_solutions

router = APIRouter(prefix="/kinematics", tags=["kinematics"])


class IKIn(BaseModel):
    pose: PoseIn
    roll: float = Field(
        0.0, description="Rotation about the approach axis, radians (q5 for the front branches)"
    )

    @field_validator("roll")
    @classmethod
    def _finite(cls, v: float) -> float:
        if not math.isfinite(v):
            raise ValueError(f"roll must be finite, got {v!r}")
        return v


@router.post("/fk", summary="Forward kinematics: joints -> (x, y, z, u, w) and T_base_ee")
async def create_fk(_: ViewerUser, body: JointsIn) -> dict[str, Any]:
    x, y, z, u, w = (float(v) for v in fk(body.joints))
    return {
        "pose": {"x": x, "y": y, "z": z, "u": u, "w": w},
        "T_base_ee": T_base_ee(body.joints).tolist(),
    }


@router.post("/ik", summary="Inverse kinematics: every branch with its joint-limit status")
async def create_ik(_: ViewerUser, body: IKIn) -> dict[str, Any]:
    solutions = ik_solutions(body.pose.as_tuple(), roll=body.roll)
    return {"solutions": [s.as_dict() for s in solutions]}
