"""REST API under ``/api``: one router per resource."""

from fastapi import APIRouter

from backend.api.routes import camera, cells, health, jobs, live, recognition, robot, sim, users

__all__ = ["api_router"]

api_router = APIRouter(prefix="/api")
for _r in (health, robot, jobs, users, cells, camera, recognition, live, sim):
    api_router.include_router(_r.router)
