"""REST API under ``/api``: one router per resource."""

from fastapi import APIRouter

from backend.api.routes import (
    calibration,
    camera,
    cells,
    health,
    jobs,
    kinematics,
    live,
    models,
    recognition,
    robot,
    sim,
    users,
)

__all__ = ["api_router"]

api_router = APIRouter(prefix="/api")
for _r in (
    health,
    robot,
    kinematics,
    jobs,
    users,
    cells,
    camera,
    recognition,
    models,
    calibration,
    sim,
    live,
):
    api_router.include_router(_r.router)
