"""Errors of the cell's motion building blocks (part of the ``VisionCellError`` hierarchy)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from robot.errors import DriverError, RobotError

if TYPE_CHECKING:
    from robot.collision import Contact
    from robot.drivers.base import MoveReport

__all__ = ["MoveAborted", "NotStill", "PathBlocked"]


class PathBlocked(RobotError):
    """The straight joint path to the target would bring the arm into an obstacle; nothing
    moved.

    Attributes
    ----------
    contacts : tuple of Contact
        What would touch what (the first configuration along the path that collides).
    """

    code = "path_blocked"

    def __init__(self, detail: str, contacts: tuple[Contact, ...] = ()) -> None:
        super().__init__(detail)
        self.contacts = contacts


class MoveAborted(RobotError):
    """A move ended before its goal (stop, emergency stop, fault).

    Attributes
    ----------
    report : MoveReport
        The driver's account of the move (``reason``: ``stopped``, ``estop``, a fault).
    """

    code = "move_aborted"

    def __init__(self, detail: str, report: MoveReport) -> None:
        super().__init__(detail)
        self.report = report


class NotStill(DriverError):
    """The arm did not come to rest within the settle time limit."""

    code = "not_still"
