"""REST API under ``/api``: one router per resource."""

from fastapi import APIRouter

from backend.api.routes import (
    audit,
    calibration,
    camera,
    cells,
    health,
    inspections,
    jobs,
    kinematics,
    live,
    models,
    recognition,
    reports,
    robot,
    sim,
    users,
    view3d,
)
from backend.api.schemas import ERROR_RESPONSES

__all__ = ["api_router"]

api_router = APIRouter(prefix="/api", responses=ERROR_RESPONSES)
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
    inspections,
    calibration,
    sim,
    live,
    view3d,
    audit,
    reports,
):
    api_router.include_router(_r.router)
