"""The object's pose from images (chapter sections 3.5 and 4.1): planar geometry, the
top view's homography refined by parallax, several views judged by the outline, and the
heights of a model's features triangulated from its taught views.

Poses are 4x4 ``T_base_obj`` (object frame: footprint centre on the belt, z up) in the
robot's base frame, metres and radians; cameras are :class:`vision.camera.PinholeCamera`
with OpenCV's frame.  Results are frozen dataclasses.
"""

from vision.pose.geometry import (
    ObjectPose,
    PoseFailed,
    closest_points,
    object_rays,
    plane_motion,
    plane_points,
    pose_apart,
    predict_along_belt,
    rests_on_too_little,
    rigid_motion_2d,
    viewing_rays,
    yaw_of,
)
from vision.pose.parallax import (
    MAX_RESIDUAL_M,
    MIN_PARALLAX_POINTS,
    estimate_pose,
    refine_with_parallax,
)
from vision.pose.silhouette import SilhouetteView, fixed_mask, silhouette_overlap
from vision.pose.structure import FeatureHeights, HeightCache, TaughtTopView, triangulate_heights
from vision.pose.views import ViewMatch, estimate_pose_views

__all__ = [
    "MAX_RESIDUAL_M",
    "MIN_PARALLAX_POINTS",
    "FeatureHeights",
    "HeightCache",
    "ObjectPose",
    "PoseFailed",
    "SilhouetteView",
    "TaughtTopView",
    "ViewMatch",
    "closest_points",
    "estimate_pose",
    "estimate_pose_views",
    "fixed_mask",
    "object_rays",
    "plane_motion",
    "plane_points",
    "pose_apart",
    "predict_along_belt",
    "refine_with_parallax",
    "rests_on_too_little",
    "rigid_motion_2d",
    "silhouette_overlap",
    "triangulate_heights",
    "viewing_rays",
    "yaw_of",
]
