"""Robot drivers behind the :class:`RobotDriver` protocol."""

from robot.drivers.base import MoveReport, RobotDriver, RobotState, StateHub
from robot.drivers.ideal import IdealDriver

__all__ = ["IdealDriver", "MoveReport", "RobotDriver", "RobotState", "StateHub"]
