"""Object segmentation (chapter section 3.2): active contours and level sets.

Contours are ``(N, 2)`` arrays of ``(x, y)`` = (column, row) pixels (OpenCV's order; note
that scikit-image uses ``(row, col)``).  Results are frozen dataclasses.
"""

from vision.segmentation.contours import (
    blob_contour,
    box_contour,
    circle_contour,
    contour_from_mask,
    ellipse_contour,
    iou,
    mask_from_contour,
    polygon_area,
    remove_loops,
    resample_closed,
)
from vision.segmentation.energy import ExternalField, edge_energy, edge_strength, external_field
from vision.segmentation.levelset import LevelSetResult, chan_vese, region_contours
from vision.segmentation.pyramid import auto_levels, gaussian_pyramid
from vision.segmentation.snake import SnakeResult, active_contour, internal_energy, internal_matrix
from vision.segmentation.warmup import warm_up

__all__ = [
    "ExternalField",
    "LevelSetResult",
    "SnakeResult",
    "active_contour",
    "auto_levels",
    "blob_contour",
    "box_contour",
    "chan_vese",
    "circle_contour",
    "contour_from_mask",
    "edge_energy",
    "edge_strength",
    "ellipse_contour",
    "external_field",
    "gaussian_pyramid",
    "internal_energy",
    "internal_matrix",
    "iou",
    "mask_from_contour",
    "polygon_area",
    "region_contours",
    "remove_loops",
    "resample_closed",
    "warm_up",
]
