"""Forward and inverse kinematics of the arm (chapter eq. 20), for tools and the console."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter
from pydantic import BaseModel, Field

from backend.api.deps import ViewerUser
from backend.api.schemas import JointsIn, PoseIn, PoseOut
from backend.api.types import RollRad
from robot.kinematics import T_base_ee, fk, ik_solutions

router = APIRouter(prefix="/kinematics", tags=["kinematics"])


class IKIn(BaseModel):
    pose: PoseIn
    roll: RollRad = Field(
        0.0, description="Rotation about the approach axis, radians (q5 for the front branches)"
    )


class FKOut(BaseModel):
    pose: PoseOut
    T_base_ee: list[list[float]] = Field(description="Pose of the flange in the base frame, 4x4")


class IKSolutionOut(BaseModel):
    joints: list[float]
    within_limits: bool
    branch: str
    violated_joints: list[int]
    detail: str


class IKOut(BaseModel):
    solutions: list[IKSolutionOut]


@router.post(
    "/fk",
    summary="Forward kinematics: joints -> (x, y, z, u, w) and T_base_ee",
    response_model=FKOut,
)
async def create_fk(_: ViewerUser, body: JointsIn) -> dict[str, Any]:
    x, y, z, u, w = (float(v) for v in fk(body.joints))
    return {
        "pose": {"x": x, "y": y, "z": z, "u": u, "w": w},
        "T_base_ee": T_base_ee(body.joints).tolist(),
    }


@router.post(
    "/ik",
    summary="Inverse kinematics: every branch with its joint-limit status",
    response_model=IKOut,
)
async def create_ik(_: ViewerUser, body: IKIn) -> dict[str, Any]:
    solutions = ik_solutions(body.pose.as_tuple(), roll=body.roll)
    return {"solutions": [s.as_dict() for s in solutions]}
