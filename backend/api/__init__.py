"""REST API under ``/api``: one router per resource."""

from fastapi import APIRouter
from fastapi.routing import APIRoute

from backend.api.fastpath import FastRead
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

__all__ = ["FAST_READS", "api_router"]

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

#: The hot reads the fast path answers from memory (``backend.api.fastpath``): what the
#: console polls.
FAST_READS = (
    FastRead(health.read_health, health.fast_read_health),
    FastRead(health.read_status, health.fast_read_status),
    FastRead(robot.read_state, robot.fast_read_state),
    FastRead(camera.read_camera_status, camera.fast_read_camera_status),
    FastRead(camera.read_frame, camera.fast_read_frame),
    FastRead(jobs.read_jobs, jobs.fast_read_jobs),
    FastRead(cells.read_cells, cells.fast_read_cells),
    FastRead(inspections.read_inspections, inspections.fast_read_inspections),
    FastRead(models.read_models, models.fast_read_models, providers=(models.get_live_index,)),
)
