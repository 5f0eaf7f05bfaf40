"""The viser 3D view of the cell."""

from backend.view3d.access import ViewAccess, ViewGrant, sign_view_link, verify_view_link
from backend.view3d.server import T_EE_CAM_PLACEHOLDER, View3D

__all__ = [
    "T_EE_CAM_PLACEHOLDER",
    "View3D",
    "ViewAccess",
    "ViewGrant",
    "sign_view_link",
    "verify_view_link",
]
