"""Values carried inside controller frames, with their token encoding.

Acknowledgements and events carry structured results: the arm's state
(:class:`ArmSnapshot`), what became of a move (:class:`MoveOutcome`), the controller's
greeting (:class:`HelloInfo`) and its limits (:class:`LimitsInfo`).  Each converts to and from
its list of tokens with ``to_args`` / ``from_args`` (``docs/serial-protocol.md`` section 4).
Angles are radians with six decimals (1 microradian), velocities rad/s, times seconds.
The grammar helpers here (strict number and word parsing) are shared with
:mod:`robot.drivers.serial.frames`.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass

from robot.errors import ProtocolError

__all__ = [
    "MAX_SEQ",
    "MOVE_STATUSES",
    "NAK_CODES",
    "PROTOCOL_VERSION",
    "TERMINAL_STATUSES",
    "ArmSnapshot",
    "HelloInfo",
    "LimitsInfo",
    "MoveOutcome",
    "fmt",
]

PROTOCOL_VERSION = 1
"""Version number exchanged in ``HELLO``."""

MAX_SEQ = 2**31 - 1
"""Largest sequence number; a host starts a new session long before reaching it."""

NAK_CODES: dict[str, str] = {
    "SYNTAX": "frame had a valid checksum but an unknown verb or malformed arguments",
    "VERSION": "protocol version not supported",
    "NOSESSION": "command before HELLO opened a session",
    "STALE": "sequence number older than the duplicate window; not executed now",
    "FULL": "receive queue full: the host exceeded its window",
    "LIMIT": "a joint value lies outside the controller's range",
    "START": "trajectory does not start at the arm's current position",
    "TRAJ": "malformed trajectory (count, times, duration)",
    "INCOMPLETE": "RUN before every point of the trajectory arrived",
    "UNKNOWN_MOVE": "no move with this id in this session",
    "USED": "move id already used for a different trajectory",
    "BUSY": "another move is executing",
    "ESTOP": "emergency stop active (or the command was flushed by one)",
    "FAULT": "the arm reports a fault",
}
"""Negative acknowledgement codes; a NAK always means the command was NOT executed."""

MOVE_STATUSES = (
    "NONE",
    "LOADING",
    "RUNNING",
    "DONE",
    "STOPPED",
    "ESTOP",
    "WATCHDOG",
    "FAULT",
    "DISCARDED",
)
"""States of a move id on the controller (``NONE``: no move in this session yet)."""

TERMINAL_STATUSES = frozenset({"DONE", "STOPPED", "ESTOP", "WATCHDOG", "FAULT", "DISCARDED"})
"""Move states after which the move id never changes again."""

INT_RE = re.compile(r"\d{1,19}")  # up to int64; ranges are checked by parse_int
FLOAT_RE = re.compile(r"-?\d{1,6}(\.\d{1,9})?")
HEX8_RE = re.compile(r"[0-9A-F]{8}")
WORD_RE = re.compile(r"[A-Z_]{1,16}")


def parse_int(tok: str, name: str, hi: int = MAX_SEQ) -> int:
    """Unsigned decimal integer in ``[0, hi]`` (no sign, no leading ``+``, no spaces)."""
    if not INT_RE.fullmatch(tok) or int(tok) > hi:
        raise ProtocolError(f"{name} must be an integer in [0, {hi}], got {tok!r}")
    return int(tok)


def parse_float(tok: str, name: str) -> float:
    """Fixed-point decimal (``-12.5``); no exponent, ``nan`` or ``inf`` on the wire."""
    if not FLOAT_RE.fullmatch(tok):
        raise ProtocolError(f"{name} must be a decimal number, got {tok!r}")
    return float(tok)


def parse_vec(toks: Sequence[str], name: str) -> tuple[float, ...]:
    """Five decimals (a joint vector)."""
    if len(toks) != 5:
        raise ProtocolError(f"{name} needs 5 values, got {len(toks)}")
    return tuple(parse_float(t, name) for t in toks)


def parse_word(tok: str, name: str, allowed: Sequence[str]) -> str:
    """One of the ``allowed`` keywords."""
    if tok not in allowed:
        raise ProtocolError(f"{name} must be one of {', '.join(allowed)}, got {tok!r}")
    return tok


def fmt(x: float, decimals: int = 6) -> str:
    """Shortest fixed-point text of ``x`` with at most ``decimals`` decimals ("-0" -> "0")."""
    s = f"{x:.{decimals}f}".rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


def fmt_vec(v: Sequence[float]) -> list[str]:
    """Tokens of a joint vector, six decimals each."""
    return [fmt(float(x)) for x in v]


def safe_text(s: str) -> str:
    """Free text made safe for a frame body (printable ASCII, no ``*``, single spaces)."""
    clean = " ".join(s.split()).replace("*", "#")
    return "".join(c if " " <= c <= "~" else "?" for c in clean)


def expect_nargs(args: Sequence[str], n: int, what: str) -> None:
    """Raise :class:`ProtocolError` unless there are exactly ``n`` argument tokens."""
    if len(args) != n:
        raise ProtocolError(f"{what} takes {n} arguments, got {len(args)}")


# -- payloads carried by acknowledgements and events -----------------------------------------
@dataclass(frozen=True)
class ArmSnapshot:
    """The arm's state as the controller reports it (``ST`` events, ``STATE`` replies).

    Attributes
    ----------
    stamp_ms : int
        Controller clock, milliseconds since it booted.
    q, qd : tuple of 5 floats
        Joint positions (rad) and velocities (rad/s).
    moving, estopped : bool
        A move is executing; an emergency stop is active.
    mid : int
        Move id of this session's current or latest move, 0 if none.
    move_status : str
        Status of ``mid`` (one of :data:`MOVE_STATUSES`).
    fault : str
        Empty when healthy, else the controller's fault text.
    gripper_on, holding : bool
        The suction gripper is on; it holds a part (vacuum established).  Flags ``G`` and
        ``H``, sent only by controllers with a gripper.
    """

    stamp_ms: int
    q: tuple[float, ...]
    qd: tuple[float, ...]
    moving: bool
    estopped: bool
    mid: int
    move_status: str
    fault: str = ""
    gripper_on: bool = False
    holding: bool = False

    def to_args(self) -> list[str]:
        flags = (
            ("M" if self.moving else "")
            + ("E" if self.estopped else "")
            + ("G" if self.gripper_on else "")
            + ("H" if self.holding else "")
        ) or "-"
        out = [str(self.stamp_ms), *fmt_vec(self.q), *(fmt(v, 4) for v in self.qd), flags]
        out += [str(self.mid), self.move_status]
        return out + ([safe_text(self.fault)] if safe_text(self.fault) else [])

    @classmethod
    def from_args(cls, args: Sequence[str]) -> ArmSnapshot:
        if len(args) < 14:
            raise ProtocolError(f"state needs at least 14 fields, got {len(args)}")
        flags = args[11]
        if not re.fullmatch(r"-|M?E?G?H?", flags) or flags == "":
            raise ProtocolError(
                f"state flags must be '-' or letters of 'MEGH' in that order, got {flags!r}"
            )
        return cls(
            stamp_ms=parse_int(args[0], "stamp_ms", 2**63),
            q=parse_vec(args[1:6], "q"),
            qd=parse_vec(args[6:11], "qd"),
            moving="M" in flags,
            estopped="E" in flags,
            mid=parse_int(args[12], "mid"),
            move_status=parse_word(args[13], "move status", MOVE_STATUSES),
            fault=" ".join(args[14:]),
            gripper_on="G" in flags,
            holding="H" in flags,
        )


@dataclass(frozen=True)
class MoveOutcome:
    """What the controller knows about one move id (``RUN``/``MOVE``/``QMV`` replies, ``DONE``).

    Attributes
    ----------
    mid : int
        Move id chosen by the host.
    status : str
        One of :data:`MOVE_STATUSES`.
    duration_s : float
        Seconds the move has run (so far, or in total once terminal).
    q : tuple of 5 floats
        Joint positions when the move ended (or now, while it runs), radians.
    error_rad : float
        Largest joint error to the move's goal at that time, radians.
    reason : str
        Free text for the operator (why it stopped, the fault).
    """

    mid: int
    status: str
    duration_s: float
    q: tuple[float, ...]
    error_rad: float
    reason: str = ""

    @property
    def terminal(self) -> bool:
        """True once the move can no longer change (done, stopped, faulted...)."""
        return self.status in TERMINAL_STATUSES

    def to_args(self) -> list[str]:
        out = [str(self.mid), self.status, fmt(self.duration_s, 4), *fmt_vec(self.q)]
        out.append(fmt(self.error_rad))
        return out + ([safe_text(self.reason)] if safe_text(self.reason) else [])

    @classmethod
    def from_args(cls, args: Sequence[str]) -> MoveOutcome:
        if len(args) < 9:
            raise ProtocolError(f"move outcome needs at least 9 fields, got {len(args)}")
        return cls(
            mid=parse_int(args[0], "mid"),
            status=parse_word(args[1], "move status", MOVE_STATUSES),
            duration_s=parse_float(args[2], "duration_s"),
            q=parse_vec(args[3:8], "q"),
            error_rad=parse_float(args[8], "error_rad"),
            reason=" ".join(args[9:]),
        )


@dataclass(frozen=True)
class HelloInfo:
    """The controller's answer to ``HELLO``.

    Attributes
    ----------
    version : int
        Protocol version spoken.
    boot_id : str
        Eight hex digits, new at every controller start (a change means it rebooted).
    resumed : bool
        True if the host's session id was the controller's current session: its duplicate
        cache and move table are kept, so unanswered commands may be resent with their seq.
    cache_depth : int
        How many recent sequence numbers the controller remembers (the duplicate window).
    window : int
        How many commands the host may have unanswered at once (receive queue depth).
    max_points : int
        Largest trajectory, in points, that the controller buffers.
    rate_hz : float
        Current state-event rate.
    name : str
        Controller name (one word).
    """

    version: int
    boot_id: str
    resumed: bool
    cache_depth: int
    window: int
    max_points: int
    rate_hz: float
    name: str

    def to_args(self) -> list[str]:
        return [
            str(self.version),
            self.boot_id,
            "RESUMED" if self.resumed else "NEW",
            str(self.cache_depth),
            str(self.window),
            str(self.max_points),
            fmt(self.rate_hz, 3),
            safe_text(self.name).replace(" ", "_") or "controller",
        ]

    @classmethod
    def from_args(cls, args: Sequence[str]) -> HelloInfo:
        expect_nargs(args, 8, "HELLO reply")
        if not HEX8_RE.fullmatch(args[1]):
            raise ProtocolError(f"boot id must be 8 hex digits, got {args[1]!r}")
        return cls(
            version=parse_int(args[0], "version"),
            boot_id=args[1],
            resumed=parse_word(args[2], "session", ("NEW", "RESUMED")) == "RESUMED",
            cache_depth=parse_int(args[3], "cache_depth"),
            window=parse_int(args[4], "window"),
            max_points=parse_int(args[5], "max_points"),
            rate_hz=parse_float(args[6], "rate_hz"),
            name=args[7],
        )


@dataclass(frozen=True)
class LimitsInfo:
    """The controller's joint ranges and speed limits (``LIMITS`` reply), SI units.

    Attributes
    ----------
    lower, upper : tuple of 5 floats
        Joint ranges, radians.
    max_velocity : tuple of 5 floats
        Speed limits at full speed, rad/s.
    """

    lower: tuple[float, ...]
    upper: tuple[float, ...]
    max_velocity: tuple[float, ...]

    def to_args(self) -> list[str]:
        return [*fmt_vec(self.lower), *fmt_vec(self.upper), *fmt_vec(self.max_velocity)]

    @classmethod
    def from_args(cls, args: Sequence[str]) -> LimitsInfo:
        expect_nargs(args, 15, "LIMITS reply")
        return cls(
            parse_vec(args[0:5], "lower"),
            parse_vec(args[5:10], "upper"),
            parse_vec(args[10:15], "v"),
        )
