"""Signed links that let the console's embedded 3D view arrive signed in."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Depends
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from pydantic import BaseModel, Field

from backend.api.deps import SettingsDep, View3DDep, ViewerUser
from backend.api.errors import ApiError
from backend.view3d.access import LINK_PATH_PREFIX, LINK_TTL_S

router = APIRouter(prefix="/view3d", tags=["view3d"])

_bearer = HTTPBearer(auto_error=False)


class ViewLinkOut(BaseModel):
    """How the console opens the embedded 3D view signed in."""

    link: str | None = Field(description="The one-use link (None: authentication is off)")
    ws_path: str = Field(description="Websocket path to open the view with")
    expires_in_s: float | None = Field(
        description="Seconds within which the link must be used (None: no link)"
    )
    viser_port: int = Field(description="Port of the 3D view's server")
    user: str | None = Field(
        None, description="Who the link signs in; left out when authentication is off"
    )


@router.post(
    "/link",
    summary="A short-lived link that signs the embedded 3D view in as you",
    response_model=ViewLinkOut,
    # ``user`` is only part of the answer with a link.
    response_model_exclude_unset=True,
)
async def create_view_link(
    user: ViewerUser,
    settings: SettingsDep,
    view: View3DDep,
    creds: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)],
) -> dict[str, Any]:
    """Open the 3D view with websocket path ``ws_path`` (``?websocket=ws://HOST:PORT{ws_path}``)
    within ``expires_in_s`` seconds; the view then shows the controls of your role for as
    long as your token stays valid.  Without authentication every view client is already
    signed in and ``link`` is null."""
    if view is None or view.access is None:
        raise ApiError(503, "unavailable", "the 3D view is not running")
    if not settings.auth_enabled or creds is None:
        return {"link": None, "ws_path": "/", "expires_in_s": None, "viser_port": view.port}
    link = await view.access.link_for_token(creds.credentials)
    if link is None:  # revoked between the dependency's check and now
        raise ApiError(401, "unauthorized", "invalid or revoked token")
    return {
        "link": link,
        "ws_path": LINK_PATH_PREFIX + link,
        "expires_in_s": LINK_TTL_S,
        "viser_port": view.port,
        "user": user.name,
    }
