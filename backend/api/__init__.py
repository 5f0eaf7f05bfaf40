"""REST API under ``/api``: one router per resource."""

from fastapi import APIRouter
from fastapi.routing import APIRoute

from backend.api.routes import (
    audit,
    belt,
    calibration,
    camera,
    cells,
    health,
    inspections,
    jobs,
    kinematics,
    live,
    models,
    recipes,
    recognition,
    reports,
    robot,
    sim,
    users,
    view3d,
)
from backend.api.schemas import BODY_ERROR_RESPONSES, ERROR_RESPONSES

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
    recipes,
    inspections,
    belt,
    calibration,
    sim,
    live,
    view3d,
    audit,
    reports,
):
    for _route in _r.router.routes:
        # Operations with a body also answer 415 (a media type or file format not accepted).
        if isinstance(_route, APIRoute) and _route.body_field is not None:
            _route.responses = {**BODY_ERROR_RESPONSES, **_route.responses}
    api_router.include_router(_r.router)
