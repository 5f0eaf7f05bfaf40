"""Robot-side domain errors, part of the one hierarchy rooted at ``VisionCellError``."""

from __future__ import annotations

from vision.errors import VisionCellError

__all__ = [
    "CommandRejected",
    "CommandSuperseded",
    "CommandTimeout",
    "DriverError",
    "JointLimitError",
    "JointLimitsBlock",
    "LinkDown",
    "OrientationNotAchievable",
    "OutOfReach",
    "ProtocolError",
    "RobotBusy",
    "RobotError",
    "SimError",
    "TrajectoryTooLong",
    "Unreachable",
]


class RobotError(VisionCellError):
    """Base of errors raised by the arm's kinematics, planning and drivers."""

    code = "robot_error"


class Unreachable(RobotError, ValueError):
    """A Cartesian target has no inverse-kinematics solution; ``detail`` says why.

    The subclasses below say which of the three reasons applies (``reason`` is a stable
    short name); all share the API error code ``"unreachable"`` (HTTP 422).
    """

    code = "unreachable"
    reason = "unreachable"


class OutOfReach(Unreachable):
    """The target position lies outside the arm's reach, whatever the joint ranges."""

    reason = "out_of_reach"


class JointLimitsBlock(Unreachable):
    """Every inverse-kinematics branch needs a joint outside its range.

    Attributes
    ----------
    joints : tuple of int
        1-based numbers of the joints that block every branch (may be empty when the
        branches are blocked by different joints; ``detail`` then lists each branch).
    """

    reason = "joint_limit"

    def __init__(self, detail: str, joints: tuple[int, ...] = ()) -> None:
        super().__init__(detail)
        self.joints = joints


class OrientationNotAchievable(Unreachable):
    """A 6-DOF target orientation is farther than allowed from what the 5-DOF arm can reach.

    Attributes
    ----------
    residual_rad : float
        Smallest rotation angle between the target orientation and a reachable one.
    """

    reason = "orientation"

    def __init__(self, detail: str, residual_rad: float) -> None:
        super().__init__(detail)
        self.residual_rad = residual_rad


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


class TrajectoryTooLong(RobotError, ValueError):
    """A planned move would last longer, or need more samples, than the planners allow.

    The bound keeps memory and playback time finite whatever the speed or the rate asked for.

    Attributes
    ----------
    duration_s : float
        Duration the plan would have, seconds.
    samples : int
        Samples the table would have.
    """

    code = "trajectory_too_long"

    def __init__(self, detail: str, *, duration_s: float, samples: int) -> None:
        super().__init__(detail)
        self.duration_s = duration_s
        self.samples = samples


class DriverError(RobotError):
    """The robot driver cannot carry out a command (disconnected, timed out, faulted)."""

    code = "driver_error"


class RobotBusy(RobotError):
    """Another job holds the motion lock, or the arm is emergency-stopped."""

    code = "robot_busy"


class LinkDown(DriverError):
    """The link to the controller is down (port missing, unplugged, or being re-opened)."""

    code = "link_down"


class CommandTimeout(DriverError):
    """A controller command got no reply in time; whether it ran is unknown."""

    code = "command_timeout"


class CommandRejected(DriverError):
    """The controller answered a command with a negative acknowledgement; it did not run.

    Attributes
    ----------
    nak_code : str
        The protocol's error code (``docs/serial-protocol.md``), e.g. ``"BUSY"``.
    """

    code = "command_rejected"

    def __init__(self, nak_code: str, detail: str) -> None:
        super().__init__(f"controller refused the command: {nak_code} {detail}".rstrip())
        self.nak_code = nak_code


class ProtocolError(DriverError):
    """Bytes on a controller link that do not form a valid frame (checksum, syntax, length).

    Attributes
    ----------
    seq : int or None
        The frame's sequence number where it could be read (so the receiver can answer
        with a negative acknowledgement), else None.
    """

    code = "protocol_error"

    def __init__(self, detail: str, *, seq: int | None = None) -> None:
        super().__init__(detail)
        self.seq = seq


class CommandSuperseded(RobotBusy):
    """A queued or unanswered command was dropped because an emergency stop overtook it.

    Attributes
    ----------
    sent : bool
        False if the command never left the host (it certainly did not run); True if it
        was on the wire before the stop (it may have run just before the stop).
    """

    code = "command_superseded"

    def __init__(self, detail: str, *, sent: bool) -> None:
        super().__init__(detail)
        self.sent = sent


class SimError(RobotError):
    """The simulated cell cannot do what was asked (no free slot, unknown object or board)."""

    code = "sim_error"
