"""Local features (chapter sections 3.3-3.4): detectors, descriptors, PCA reduction.

``extract(image, method)`` returns a frozen :class:`Features`; keypoints are in pixels,
``(x, y)`` = (column, row), angles in radians counter-clockwise on screen.
"""

from vision.features.extract import COLOUR_METHODS, METHODS, extract, grey_from_image
from vision.features.opencv import keypoints_from_cv, keypoints_to_cv
from vision.features.surf import surf_describe, surf_features, surf_orientation
from vision.features.types import Features, Keypoints

__all__ = [
    "COLOUR_METHODS",
    "METHODS",
    "Features",
    "Keypoints",
    "extract",
    "grey_from_image",
    "keypoints_from_cv",
    "keypoints_to_cv",
    "surf_describe",
    "surf_features",
    "surf_orientation",
]
