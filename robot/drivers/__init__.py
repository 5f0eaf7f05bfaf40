"""Robot drivers behind the :class:`RobotDriver` protocol, and conveyors behind
:class:`Conveyor`."""

from robot.drivers.base import MoveReport, RobotDriver, RobotState, StateHub
from robot.drivers.conveyor import BeltStatus, Conveyor, FixedStation
from robot.drivers.ideal import IdealDriver

__all__ = [
    "BeltStatus",
    "Conveyor",
    "FixedStation",
    "IdealDriver",
    "MoveReport",
    "RobotDriver",
    "RobotState",
    "StateHub",
]
