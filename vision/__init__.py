"""Pure image algorithms: camera model, calibration, segmentation, features, recognition.

Submodules are imported on demand (``from vision.camera import PinholeCamera``) so that
importing one piece does not load OpenCV for the others.
"""

from vision.errors import (
    CalibrationError,
    CameraError,
    ImageError,
    RecognitionFailed,
    StreamEnded,
    VisionCellError,
)

__all__ = [
    "CalibrationError",
    "CameraError",
    "ImageError",
    "RecognitionFailed",
    "StreamEnded",
    "VisionCellError",
]
