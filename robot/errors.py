"""Robot-side domain errors, part of the one hierarchy rooted at ``VisionCellError``."""

from __future__ import annotations

from vision.errors import VisionCellError

__all__ = ["DriverError", "JointLimitError", "RobotBusy", "RobotError", "SimError", "Unreachable"]


class RobotError(VisionCellError):
    """Base of errors raised by the arm's kinematics, planning and drivers."""

    code = "robot_error"
    http_status = 409


class Unreachable(RobotError, ValueError):
    """A Cartesian target has no inverse-kinematics solution; ``detail`` says why."""

    code = "unreachable"
    http_status = 422


class JointLimitError(RobotError, ValueError):
    """A joint value lies outside its range.

    Attributes
    ----------
    joint : int
        1-based joint number (q1..q5), as in chapter Table 1.
    value_rad : float
        The offending value in radians.
    limits_rad : tuple of float
        The allowed ``(low, high)`` range in radians.
    """

    code = "joint_limit"
    http_status = 422

    def __init__(self, joint: int, value_rad: float, limits_rad: tuple[float, float]) -> None:
        import math

        lo, hi = limits_rad
        super().__init__(
            f"q{joint} = {value_rad:.6g} rad ({math.degrees(value_rad):.2f} deg) is outside "
            f"its range [{lo:.6g}, {hi:.6g}] rad "
            f"([{math.degrees(lo):.2f}, {math.degrees(hi):.2f}] deg)"
        )
        self.joint = joint
        self.value_rad = value_rad
        self.limits_rad = limits_rad


class DriverError(RobotError):
    """The robot driver cannot carry out a command (disconnected, timed out, faulted)."""

    code = "driver_error"
    http_status = 503


class RobotBusy(RobotError):
    """Another job holds the motion lock, or the arm is emergency-stopped."""

    code = "robot_busy"
    http_status = 409


class SimError(RobotError):
    """The simulated cell cannot do what was asked (no free slot, unknown object or board)."""

    code = "sim_error"
    http_status = 409
