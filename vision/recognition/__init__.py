"""Recognition of trained objects (chapter section 3.5 and the automatic threshold of
section 6): an index of trained views with approximate-nearest-neighbour retrieval, scores
in [0, 1] and the 2D decision, automatic thresholds, and the viewpoint policies of 3D
recognition. Pure functions of images and an index: no robot, no backend.
"""

from vision.recognition.index import (
    FORMAT_VERSION,
    VIEWPOINTS,
    IndexFormatError,
    TrainedView,
    ViewIndex,
)
from vision.recognition.plots import plot_threshold
from vision.recognition.recognise import (
    DECISIONS,
    DEFAULT_MARGIN,
    DEFAULT_THRESHOLD,
    Candidate,
    Recognition,
    decide,
    recognise,
)
from vision.recognition.threshold import (
    RULES,
    THRESHOLD_FLOOR,
    ThresholdChoice,
    choose_threshold,
    conformal_threshold,
    floor_threshold,
    youden_threshold,
)
from vision.recognition.views import POLICIES, ViewsRecognition, recognise_views

__all__ = [
    "DECISIONS",
    "DEFAULT_MARGIN",
    "DEFAULT_THRESHOLD",
    "FORMAT_VERSION",
    "POLICIES",
    "RULES",
    "THRESHOLD_FLOOR",
    "VIEWPOINTS",
    "Candidate",
    "IndexFormatError",
    "Recognition",
    "ThresholdChoice",
    "TrainedView",
    "ViewIndex",
    "ViewsRecognition",
    "choose_threshold",
    "conformal_threshold",
    "decide",
    "floor_threshold",
    "plot_threshold",
    "recognise",
    "recognise_views",
    "youden_threshold",
]
