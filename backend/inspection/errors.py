"""Why an inspection cannot start or goes no further (domain errors, no HTTP)."""

from __future__ import annotations

from vision.errors import NothingTrained, VisionCellError

__all__ = ["NOT_TRAINED", "CarriedAway", "NoObject", "NotReady"]

#: Why an inspection cannot start before a teach (the console links its Models page on the
#: error's code, ``nothing_trained``).
NOT_TRAINED = (
    "no trained views: teach a model first (the console's Models page, "
    "`visioncell models teach NAME` or POST /api/models/{id}/teach)"
)


class CarriedAway(VisionCellError):
    """Constant speed: the belt carried the object past its end before a side view."""

    code = "carried_away"


class NotReady(NothingTrained):
    """A setup step is missing (nothing trained, no empty-belt background of the top view):
    no inspection can start; a run ends with the reason."""


class NoObject(VisionCellError):
    """No object came to the station in time."""

    code = "no_object"
