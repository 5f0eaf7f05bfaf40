"""Robot-side domain errors, part of the one hierarchy rooted at ``VisionCellError``."""

from __future__ import annotations

from vision.errors import VisionCellError

__all__ = [
    "CommandRejected",
    "CommandSuperseded",
    "CommandTimeout",
    "DriverError",
    "JointLimitError",
    "LinkDown",
    "ProtocolError",
    "RobotBusy",
    "RobotError",
    "Unreachable",
]


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
