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

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import ClassVar

from robot.drivers.serial.framing import MAX_LINE_BYTES, LineReader, seal, unseal
from robot.drivers.serial.payloads import (
    HEX8_RE,
    MOVE_STATUSES,
    NAK_CODES,
    PROTOCOL_VERSION,
    TERMINAL_STATUSES,
    WORD_RE,
    ArmSnapshot,
    HelloInfo,
    LimitsInfo,
    MoveOutcome,
    expect_nargs,
    fmt,
    fmt_vec,
    parse_float,
    parse_int,
    parse_vec,
    parse_word,
    safe_text,
)
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
    "Grip",
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
        expect_nargs(args, 0, cls.VERB)
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
        expect_nargs(args, 2, "HELLO")
        if not HEX8_RE.fullmatch(args[0]):
            raise ProtocolError(f"session must be 8 upper-case hex digits, got {args[0]!r}")
        return cls(seq, args[0], parse_int(args[1], "version"))


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
        expect_nargs(args, 1, "RATE")
        return cls(seq, parse_float(args[0], "rate_hz"))


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
        if self.speed is not None and self.duration_s is None:
            mode = ["S", fmt(self.speed, 4)]
        elif self.duration_s is not None and self.speed is None:
            mode = ["T", fmt(self.duration_s, 4)]
        else:
            raise ValueError("MOVE needs exactly one of duration_s and speed")
        return [str(self.mid), *fmt_vec(self.q), *mode]

    @classmethod
    def from_args(cls, seq: int, args: Sequence[str]) -> MoveJoints:
        expect_nargs(args, 8, "MOVE")
        mode = parse_word(args[6], "MOVE mode", ("T", "S"))
        value = parse_float(args[7], "duration_s" if mode == "T" else "speed")
        q = parse_vec(args[1:6], "q")
        if mode == "T":
            return cls(seq, parse_int(args[0], "mid"), q, duration_s=value)
        return cls(seq, parse_int(args[0], "mid"), q, speed=value)


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
        expect_nargs(args, 2, "TBEGIN")
        return cls(seq, parse_int(args[0], "mid"), parse_int(args[1], "n_points"))


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
            *fmt_vec(self.q),
            *fmt_vec(self.qd),
        ]

    @classmethod
    def from_args(cls, seq: int, args: Sequence[str]) -> TrajPoint:
        expect_nargs(args, 13, "TP")
        return cls(
            seq,
            parse_int(args[0], "mid"),
            parse_int(args[1], "index"),
            parse_float(args[2], "t_s"),
            parse_vec(args[3:8], "q"),
            parse_vec(args[8:13], "qd"),
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
        expect_nargs(args, 1, "RUN")
        return cls(seq, parse_int(args[0], "mid"))


@dataclass(frozen=True)
class QueryMove(Command):
    """Ask for the :class:`MoveOutcome` of move ``mid``."""

    mid: int
    VERB: ClassVar[str] = "QMV"

    def args(self) -> list[str]:
        return [str(self.mid)]

    @classmethod
    def from_args(cls, seq: int, args: Sequence[str]) -> QueryMove:
        expect_nargs(args, 1, "QMV")
        return cls(seq, parse_int(args[0], "mid"))


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


@dataclass(frozen=True)
class Grip(Command):
    """Suction gripper on (``GRIP 1``) or off (``GRIP 0``); the reply ``A s GRIP <on>
    <holding>`` says whether a part is held."""

    on: bool
    VERB: ClassVar[str] = "GRIP"

    def args(self) -> list[str]:
        return ["1" if self.on else "0"]

    @classmethod
    def from_args(cls, seq: int, args: Sequence[str]) -> Grip:
        expect_nargs(args, 1, "GRIP")
        return cls(seq, parse_word(args[0], "GRIP state", ("0", "1")) == "1")

    @staticmethod
    def parse_reply(args: Sequence[str]) -> tuple[bool, bool]:
        """``(on, holding)`` from the acknowledgement's arguments."""
        expect_nargs(args, 2, "GRIP reply")
        on = parse_word(args[0], "GRIP reply state", ("0", "1")) == "1"
        return on, parse_word(args[1], "GRIP reply holding", ("0", "1")) == "1"


COMMANDS: dict[str, type[Command]] = {
    c.VERB: c
    for c in (
        Hello, Ping, GetState, GetLimits, SetRate, MoveJoints, TrajBegin, TrajPoint, Run,
        QueryMove, Stop, EStop, Reset, Grip,
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
        object.__setattr__(self, "detail", safe_text(self.detail))

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
    seq = parse_int(num, "sequence number")
    try:
        if kind == "C":
            cls = COMMANDS.get(verb)
            if cls is None:
                raise ProtocolError(f"unknown command verb {verb!r}")
            return cls.from_args(seq, args)
        if kind == "A":
            if not WORD_RE.fullmatch(verb):
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
