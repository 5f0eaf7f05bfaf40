"""The viser 3D view of the cell."""

from backend.view3d.server import T_EE_CAM_PLACEHOLDER, View3D

__all__ = ["T_EE_CAM_PLACEHOLDER", "View3D"]
