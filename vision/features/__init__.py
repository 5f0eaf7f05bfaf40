"""Local features (chapter sections 3.3-3.4): detectors, descriptors, PCA reduction.

``extract(image, method)`` returns a frozen :class:`Features`; keypoints are in pixels,
``(x, y)`` = (column, row), angles in radians counter-clockwise on screen.

SURF's functions (``surf_features``, ``surf_keypoints``, ``surf_describe``,
``surf_orientation``) are re-exported lazily: importing them loads numba, which the other
methods do not need.
"""

from typing import Any

from vision.features.colour import colour_features, m_images
from vision.features.extract import COLOUR_METHODS, METHODS, extract, grey_from_image
from vision.features.gloh import gloh_features
from vision.features.opencv import keypoints_from_cv, keypoints_to_cv
from vision.features.pca import PcaBasis, default_basis, fit_pca, load_npz, save_npz
from vision.features.pcasift import pca_sift_features
from vision.features.types import Features, Keypoints

__all__ = [
    "COLOUR_METHODS",
    "METHODS",
    "Features",
    "Keypoints",
    "PcaBasis",
    "colour_features",
    "default_basis",
    "extract",
    "fit_pca",
    "gloh_features",
    "grey_from_image",
    "keypoints_from_cv",
    "keypoints_to_cv",
    "load_npz",
    "m_images",
    "pca_sift_features",
    "save_npz",
    "surf_describe",
    "surf_features",
    "surf_keypoints",
    "surf_orientation",
]

_SURF_NAMES = frozenset({"surf_describe", "surf_features", "surf_keypoints", "surf_orientation"})


def __getattr__(name: str) -> Any:
    if name in _SURF_NAMES:
        from vision.features import surf

        return getattr(surf, name)
    raise AttributeError(f"module 'vision.features' has no attribute {name!r}")
