"""Frames of the controller protocol as frozen dataclasses, with their text encoding.

Every frame body is a sequence of tokens separated by single spaces
(``docs/serial-protocol.md`` section 3):

* host commands ``C <seq> <VERB> [args]`` (:class:`Command` subclasses),
* acknowledgements ``A <seq> <VERB> [results]`` (:class:`Ack`),
* negative acknowledgements ``N <seq> <CODE> [detail]`` (:class:`Nak`),
* controller events ``E <eseq> <TYPE> [args]`` (:class:`StateEvent`, :class:`DoneEvent`).

Structured results that ride in acknowledgements and events (:class:`ArmSnapshot`,
:class:`MoveOutcome`, :class:`HelloInfo`, :class:`LimitsInfo`) convert to and from their
token lists with ``to_args`` / ``from_args``.  Angles are radians with six decimals
(1 microradian), times are seconds.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, fields
from typing import ClassVar

from robot.drivers.serial.framing import MAX_LINE_BYTES, LineReader, seal, unseal
from robot.errors import ProtocolError

__all__ = [
    "MOVE_STATUSES",
    "NAK_CODES",
    "PROTOCOL_VERSION",
    "TERMINAL_STATUSES",
    "Ack",
    "ArmSnapshot",
    "Command",
    "DoneEvent",
    "EStop",
    "Event",
    "Frame",
    "FrameParser",
    "GetLimits",
    "GetState",
    "Hello",
    "HelloInfo",
    "LimitsInfo",
    "MoveJoints",
    "MoveOutcome",
    "Nak",
    "Ping",
    "QueryMove",
    "Reset",
    "Run",
    "SetRate",
    "StateEvent",
    "Stop",
    "TrajBegin",
    "TrajPoint",
    "decode",
    "decode_body",
    "encode",
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

_INT = re.compile(r"\d{1,10}")
_FLOAT = re.compile(r"-?\d{1,6}(\.\d{1,9})?")
_HEX8 = re.compile(r"[0-9A-F]{8}")
_WORD = re.compile(r"[A-Z_]{1,16}")


def _int(tok: str, name: str, hi: int = MAX_SEQ) -> int:
    if not _INT.fullmatch(tok) or int(tok) > hi:
        raise ProtocolError(f"{name} must be an integer in [0, {hi}], got {tok!r}")
    return int(tok)


def _float(tok: str, name: str) -> float:
    if not _FLOAT.fullmatch(tok):
        raise ProtocolError(f"{name} must be a decimal number, got {tok!r}")
    return float(tok)


def _vec(toks: Sequence[str], name: str) -> tuple[float, ...]:
    if len(toks) != 5:
        raise ProtocolError(f"{name} needs 5 values, got {len(toks)}")
    return tuple(_float(t, name) for t in toks)


def _word(tok: str, name: str, allowed: Sequence[str]) -> str:
    if tok not in allowed:
        raise ProtocolError(f"{name} must be one of {', '.join(allowed)}, got {tok!r}")
    return tok


def fmt(x: float, decimals: int = 6) -> str:
    """Shortest fixed-point text of ``x`` with at most ``decimals`` decimals ("-0" -> "0")."""
    s = f"{x:.{decimals}f}".rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


def _fmt_vec(v: Sequence[float]) -> list[str]:
    return [fmt(float(x)) for x in v]


def _text(s: str) -> str:
    """Free text made safe for a frame body (printable ASCII, no ``*``, single spaces)."""
    clean = " ".join(s.split()).replace("*", "#")
    return "".join(c if " " <= c <= "~" else "?" for c in clean)


def _nargs(args: Sequence[str], n: int, what: str) -> None:
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
    """

    stamp_ms: int
    q: tuple[float, ...]
    qd: tuple[float, ...]
    moving: bool
    estopped: bool
    mid: int
    move_status: str
    fault: str = ""

    def to_args(self) -> list[str]:
        flags = ("M" if self.moving else "") + ("E" if self.estopped else "") or "-"
        out = [str(self.stamp_ms), *_fmt_vec(self.q), *(fmt(v, 4) for v in self.qd), flags]
        out += [str(self.mid), self.move_status]
        return out + ([_text(self.fault)] if _text(self.fault) else [])

    @classmethod
    def from_args(cls, args: Sequence[str]) -> ArmSnapshot:
        if len(args) < 14:
            raise ProtocolError(f"state needs at least 14 fields, got {len(args)}")
        flags = args[11]
        if not re.fullmatch(r"-|M?E?", flags) or flags == "":
            raise ProtocolError(f"state flags must be '-', 'M', 'E' or 'ME', got {flags!r}")
        return cls(
            stamp_ms=_int(args[0], "stamp_ms", 2**63),
            q=_vec(args[1:6], "q"),
            qd=_vec(args[6:11], "qd"),
            moving="M" in flags,
            estopped="E" in flags,
            mid=_int(args[12], "mid"),
            move_status=_word(args[13], "move status", MOVE_STATUSES),
            fault=" ".join(args[14:]),
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
        out = [str(self.mid), self.status, fmt(self.duration_s, 4), *_fmt_vec(self.q)]
        out.append(fmt(self.error_rad))
        return out + ([_text(self.reason)] if _text(self.reason) else [])

    @classmethod
    def from_args(cls, args: Sequence[str]) -> MoveOutcome:
        if len(args) < 9:
            raise ProtocolError(f"move outcome needs at least 9 fields, got {len(args)}")
        return cls(
            mid=_int(args[0], "mid"),
            status=_word(args[1], "move status", MOVE_STATUSES),
            duration_s=_float(args[2], "duration_s"),
            q=_vec(args[3:8], "q"),
            error_rad=_float(args[8], "error_rad"),
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
            _text(self.name).replace(" ", "_") or "controller",
        ]

    @classmethod
    def from_args(cls, args: Sequence[str]) -> HelloInfo:
        _nargs(args, 8, "HELLO reply")
        if not _HEX8.fullmatch(args[1]):
            raise ProtocolError(f"boot id must be 8 hex digits, got {args[1]!r}")
        return cls(
            version=_int(args[0], "version"),
            boot_id=args[1],
            resumed=_word(args[2], "session", ("NEW", "RESUMED")) == "RESUMED",
            cache_depth=_int(args[3], "cache_depth"),
            window=_int(args[4], "window"),
            max_points=_int(args[5], "max_points"),
            rate_hz=_float(args[6], "rate_hz"),
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
        return [*_fmt_vec(self.lower), *_fmt_vec(self.upper), *_fmt_vec(self.max_velocity)]

    @classmethod
    def from_args(cls, args: Sequence[str]) -> LimitsInfo:
        _nargs(args, 15, "LIMITS reply")
        return cls(_vec(args[0:5], "lower"), _vec(args[5:10], "upper"), _vec(args[10:15], "v"))


# -- frames ------------------------------------------------------------------------------------
class Frame:
    """Base of every frame; :func:`encode` turns one into wire bytes."""

    def body(self) -> str:  # pragma: no cover - overridden
        raise NotImplementedError


@dataclass(frozen=True)
class Command(Frame):
    """A host command; ``seq`` identifies it for replies and duplicate detection."""

    seq: int
    VERB: ClassVar[str] = ""
    MOTION: ClassVar[bool] = False

    def args(self) -> list[str]:
        """Argument tokens after the verb (none by default)."""
        return []

    def body(self) -> str:
        return " ".join(["C", str(self.seq), self.VERB, *self.args()])

    @classmethod
    def from_args(cls, seq: int, args: Sequence[str]) -> Command:
        """Build the command from its argument tokens (none by default)."""
        _nargs(args, 0, cls.VERB)
        return cls(seq)


@dataclass(frozen=True)
class Hello(Command):
    """Open or resume session ``session`` (8 hex digits, chosen by the host)."""

    session: str
    version: int = PROTOCOL_VERSION
    VERB: ClassVar[str] = "HELLO"

    def args(self) -> list[str]:
        return [self.session, str(self.version)]

    @classmethod
    def from_args(cls, seq: int, args: Sequence[str]) -> Hello:
        _nargs(args, 2, "HELLO")
        if not _HEX8.fullmatch(args[0]):
            raise ProtocolError(f"session must be 8 upper-case hex digits, got {args[0]!r}")
        return cls(seq, args[0], _int(args[1], "version"))


@dataclass(frozen=True)
class Ping(Command):
    """Liveness check and heartbeat; the reply carries the controller clock in ms."""

    VERB: ClassVar[str] = "PING"


@dataclass(frozen=True)
class GetState(Command):
    """Ask for one :class:`ArmSnapshot`."""

    VERB: ClassVar[str] = "STATE"


@dataclass(frozen=True)
class GetLimits(Command):
    """Ask for the controller's :class:`LimitsInfo`."""

    VERB: ClassVar[str] = "LIMITS"


@dataclass(frozen=True)
class SetRate(Command):
    """Set the state-event rate in Hz (0 stops the stream)."""

    rate_hz: float
    VERB: ClassVar[str] = "RATE"

    def args(self) -> list[str]:
        return [fmt(self.rate_hz, 3)]

    @classmethod
    def from_args(cls, seq: int, args: Sequence[str]) -> SetRate:
        _nargs(args, 1, "RATE")
        return cls(seq, _float(args[0], "rate_hz"))


@dataclass(frozen=True)
class MoveJoints(Command):
    """Point-to-point joint move planned by the controller: a duration or a speed fraction."""

    mid: int
    q: tuple[float, ...]
    duration_s: float | None = None
    speed: float | None = None
    VERB: ClassVar[str] = "MOVE"
    MOTION: ClassVar[bool] = True

    def args(self) -> list[str]:
        if (self.duration_s is None) == (self.speed is None):
            raise ValueError("MOVE needs exactly one of duration_s and speed")
        mode = ["T", fmt(self.duration_s, 4)] if self.speed is None else ["S", fmt(self.speed, 4)]
        return [str(self.mid), *_fmt_vec(self.q), *mode]

    @classmethod
    def from_args(cls, seq: int, args: Sequence[str]) -> MoveJoints:
        _nargs(args, 8, "MOVE")
        mode = _word(args[6], "MOVE mode", ("T", "S"))
        value = _float(args[7], "duration_s" if mode == "T" else "speed")
        q = _vec(args[1:6], "q")
        if mode == "T":
            return cls(seq, _int(args[0], "mid"), q, duration_s=value)
        return cls(seq, _int(args[0], "mid"), q, speed=value)


@dataclass(frozen=True)
class TrajBegin(Command):
    """Open trajectory ``mid`` with ``n_points`` points to come."""

    mid: int
    n_points: int
    VERB: ClassVar[str] = "TBEGIN"

    def args(self) -> list[str]:
        return [str(self.mid), str(self.n_points)]

    @classmethod
    def from_args(cls, seq: int, args: Sequence[str]) -> TrajBegin:
        _nargs(args, 2, "TBEGIN")
        return cls(seq, _int(args[0], "mid"), _int(args[1], "n_points"))


@dataclass(frozen=True)
class TrajPoint(Command):
    """Point ``index`` of trajectory ``mid``: time (s), positions (rad), velocities (rad/s)."""

    mid: int
    index: int
    t_s: float
    q: tuple[float, ...]
    qd: tuple[float, ...]
    VERB: ClassVar[str] = "TP"

    def args(self) -> list[str]:
        return [
            str(self.mid),
            str(self.index),
            fmt(self.t_s),
            *_fmt_vec(self.q),
            *_fmt_vec(self.qd),
        ]

    @classmethod
    def from_args(cls, seq: int, args: Sequence[str]) -> TrajPoint:
        _nargs(args, 13, "TP")
        return cls(
            seq,
            _int(args[0], "mid"),
            _int(args[1], "index"),
            _float(args[2], "t_s"),
            _vec(args[3:8], "q"),
            _vec(args[8:13], "qd"),
        )


@dataclass(frozen=True)
class Run(Command):
    """Start the fully loaded trajectory ``mid`` (at most once per session)."""

    mid: int
    VERB: ClassVar[str] = "RUN"
    MOTION: ClassVar[bool] = True

    def args(self) -> list[str]:
        return [str(self.mid)]

    @classmethod
    def from_args(cls, seq: int, args: Sequence[str]) -> Run:
        _nargs(args, 1, "RUN")
        return cls(seq, _int(args[0], "mid"))


@dataclass(frozen=True)
class QueryMove(Command):
    """Ask for the :class:`MoveOutcome` of move ``mid``."""

    mid: int
    VERB: ClassVar[str] = "QMV"

    def args(self) -> list[str]:
        return [str(self.mid)]

    @classmethod
    def from_args(cls, seq: int, args: Sequence[str]) -> QueryMove:
        _nargs(args, 1, "QMV")
        return cls(seq, _int(args[0], "mid"))


@dataclass(frozen=True)
class Stop(Command):
    """Controlled stop of the current move; the arm holds where it is."""

    VERB: ClassVar[str] = "STOP"


@dataclass(frozen=True)
class EStop(Command):
    """Emergency stop: halt at once, drop queued commands, refuse motion until RESET."""

    VERB: ClassVar[str] = "ESTOP"


@dataclass(frozen=True)
class Reset(Command):
    """Clear an emergency stop or a fault."""

    VERB: ClassVar[str] = "RESET"


COMMANDS: dict[str, type[Command]] = {
    c.VERB: c
    for c in (
        Hello, Ping, GetState, GetLimits, SetRate, MoveJoints, TrajBegin, TrajPoint, Run,
        QueryMove, Stop, EStop, Reset,
    )
}  # fmt: skip


@dataclass(frozen=True)
class Ack(Frame):
    """Positive acknowledgement of command ``seq``: it was executed; ``args`` are results."""

    seq: int
    verb: str
    args: tuple[str, ...] = ()

    def body(self) -> str:
        return " ".join(["A", str(self.seq), self.verb, *self.args])


@dataclass(frozen=True)
class Nak(Frame):
    """Negative acknowledgement of command ``seq``: NOT executed, for reason ``code``."""

    seq: int
    code: str
    detail: str = ""

    def __post_init__(self) -> None:
        if self.code not in NAK_CODES:
            raise ValueError(f"code must be one of {sorted(NAK_CODES)}, got {self.code!r}")
        object.__setattr__(self, "detail", _text(self.detail))

    def body(self) -> str:
        return " ".join(["N", str(self.seq), self.code, *([self.detail] if self.detail else [])])


@dataclass(frozen=True)
class Event(Frame):
    """An unsolicited controller frame; ``eseq`` counts events so gaps show lost ones."""

    eseq: int


@dataclass(frozen=True)
class StateEvent(Event):
    """Periodic arm state (``ST``)."""

    state: ArmSnapshot

    def body(self) -> str:
        return " ".join(["E", str(self.eseq), "ST", *self.state.to_args()])


@dataclass(frozen=True)
class DoneEvent(Event):
    """A move reached a terminal status (``DONE``)."""

    outcome: MoveOutcome

    def body(self) -> str:
        return " ".join(["E", str(self.eseq), "DONE", *self.outcome.to_args()])


def encode(frame: Frame) -> bytes:
    """Wire bytes of ``frame`` (body, ``*``, CRC, LF)."""
    return seal(frame.body())


def decode_body(body: str) -> Frame:
    """Parse one checked frame body.

    Raises
    ------
    ProtocolError
        On any grammar violation; its ``seq`` is set when the sequence number was readable,
        so a controller can answer ``N <seq> SYNTAX``.
    """
    toks = body.split(" ")
    if len(toks) < 3 or "" in toks:
        raise ProtocolError(
            f"a frame needs kind, number and verb separated by single spaces: {body[:40]!r}"
        )
    kind, num, verb, args = toks[0], toks[1], toks[2], toks[3:]
    seq = _int(num, "sequence number")
    try:
        if kind == "C":
            cls = COMMANDS.get(verb)
            if cls is None:
                raise ProtocolError(f"unknown command verb {verb!r}")
            return cls.from_args(seq, args)
        if kind == "A":
            if not _WORD.fullmatch(verb):
                raise ProtocolError(f"bad acknowledged verb {verb!r}")
            return Ack(seq, verb, tuple(args))
        if kind == "N":
            if verb not in NAK_CODES:
                raise ProtocolError(f"unknown NAK code {verb!r}")
            return Nak(seq, verb, " ".join(args))
        if kind == "E":
            if verb == "ST":
                return StateEvent(seq, ArmSnapshot.from_args(args))
            if verb == "DONE":
                return DoneEvent(seq, MoveOutcome.from_args(args))
            raise ProtocolError(f"unknown event type {verb!r}")
    except ProtocolError as exc:
        # The number is only worth quoting back for a command (so the controller can NAK it).
        raise ProtocolError(str(exc), seq=seq if kind == "C" else None) from None
    raise ProtocolError(f"unknown frame kind {kind!r}")


def decode(line: bytes) -> Frame:
    """Check and parse one received line (without LF): checksum first, then grammar."""
    return decode_body(unseal(line))


class FrameParser:
    """Byte stream in, checked frames out: :class:`LineReader` + :func:`decode`.

    Parameters
    ----------
    on_reject : callable, optional
        Called with the :class:`ProtocolError` of every rejected line (bad checksum, bad
        grammar).  Over-long lines are counted by :attr:`reader` (``overlong``).
    max_line_bytes : int
        Longest accepted line.
    """

    def __init__(
        self,
        on_reject: Callable[[ProtocolError], None] | None = None,
        *,
        max_line_bytes: int = MAX_LINE_BYTES,
    ) -> None:
        self.reader = LineReader(max_line_bytes)
        self.on_reject = on_reject
        self.accepted = 0
        self.rejected = 0

    def feed(self, data: bytes) -> list[Frame]:
        """Add received bytes; return the frames completed by them, in order."""
        out: list[Frame] = []
        for line in self.reader.feed(data):
            try:
                out.append(decode(line))
            except ProtocolError as exc:
                self.rejected += 1
                if self.on_reject is not None:
                    self.on_reject(exc)
        self.accepted += len(out)
        return out

    def clear(self) -> None:
        """Drop any partial line (after the link was re-opened)."""
        self.reader.clear()


def frame_fields(frame: Frame) -> dict[str, object]:
    """The dataclass fields of ``frame`` as a dict (for logs and tests)."""
    return {f.name: getattr(frame, f.name) for f in fields(frame)}  # type: ignore[arg-type]
