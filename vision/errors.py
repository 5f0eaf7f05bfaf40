"""The one exception hierarchy of VisionCell.

Every domain error raised by ``vision``, ``robot`` or ``backend`` derives from
:class:`VisionCellError`.  The root lives here because ``vision`` is the one package that
imports nothing else of ours; ``robot.errors`` subclasses it.  Each class carries a stable
``code`` (the ``error`` field of the API's JSON body) and nothing of HTTP: the API's edge
holds the one table from error classes to HTTP statuses.
"""

from __future__ import annotations


class VisionCellError(Exception):
    """Root of all VisionCell domain errors."""

    code: str = "visioncell_error"

    def __init__(self, detail: str) -> None:
        super().__init__(detail)
        self.detail = detail


class ImageError(VisionCellError, ValueError):
    """An image has the wrong dtype, shape or content."""

    code = "bad_image"


class CameraError(VisionCellError):
    """An image source failed (device gone, stream ended, folder empty)."""

    code = "camera_error"


class StreamEnded(CameraError):
    """A finite source (a video file, a folder replayed without looping) has no more frames."""

    code = "stream_ended"


class CalibrationError(VisionCellError):
    """A calibration cannot be solved (too few views, no pattern, degenerate motion)."""

    code = "calibration_failed"


class RecognitionFailed(VisionCellError):
    """Recognition could not decide on an object."""

    code = "recognition_failed"


class InvalidInput(VisionCellError, ValueError):
    """A value given by a user (request, file, command line) is out of range or malformed.

    Raised where user input is validated beyond what a schema can say (the contents of an
    uploaded file, a combination of fields).  It is also a ``ValueError`` so that callers
    catching bad values keep working; the API answers 422 (code ``invalid_value``; a
    request refused by its schema has ``validation_error``).
    """

    code = "invalid_value"


class NotFound(VisionCellError):
    """The thing named by an id or a name does not exist (a row, a job, a light, a plot)."""

    code = "not_found"


class Conflict(VisionCellError):
    """The request clashes with the current state (a name already taken, a locked resource)."""

    code = "conflict"


class NothingTrained(Conflict):
    """An inspection was asked for before any model was taught: there is nothing to
    recognise yet (the console sends the user to its Models page on this code)."""

    code = "nothing_trained"
