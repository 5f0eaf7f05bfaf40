"""The arm: model, kinematics, trajectories, drivers and the simulated cell."""

from robot.errors import (
    DriverError,
    JointLimitError,
    JointLimitsBlock,
    OrientationNotAchievable,
    OutOfReach,
    RobotBusy,
    RobotError,
    Unreachable,
)
from robot.model import ASEA, ArmModel, check_joints

__all__ = [
    "ASEA",
    "ArmModel",
    "DriverError",
    "JointLimitError",
    "JointLimitsBlock",
    "OrientationNotAchievable",
    "OutOfReach",
    "RobotBusy",
    "RobotError",
    "Unreachable",
    "check_joints",
]
