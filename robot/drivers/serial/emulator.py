"""A controller emulator: the device side of the serial protocol on a pseudo-terminal.

:class:`Emulator` plays the arm controller of ``docs/serial-protocol.md`` on a pseudo-terminal
(:class:`~robot.drivers.serial.ptyport.PtyPort`) and carries out motion with any
:class:`~robot.drivers.base.RobotDriver` (the MuJoCo simulator where it exists, else the
ideal driver).  So the whole serial stack, from ``SerialDriver`` down to the bytes, runs in
tests and demos without hardware.  Fault injection
(:class:`~robot.drivers.serial.faults.FaultConfig`) drops, corrupts, truncates, delays and
garbles lines, and makes the port vanish and come back at the same path.

The controller's rules (section 5 of the protocol document):

* a session starts with ``HELLO <session>``; the same session id resumes it (duplicate cache
  and move table kept), a new id starts afresh (sequence numbers up to the HELLO's are stale);
* each command's reply is cached under its sequence number (the last ``cache_depth``
  numbers); a repeated number is answered from the cache and NOT executed again;
* each move id runs at most once per session, whatever sequence numbers ask for it (the move
  table, :class:`~robot.drivers.serial.movetable.MoveTable`);
* the emergency stop is acted on in the receive path, ahead of queued commands, which are
  answered ``NAK ESTOP`` and not executed;
* if the host falls silent for ``watchdog_s`` during a move, the arm is stopped (``WATCHDOG``)
  and the state stream pauses until the host speaks again.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import random
import secrets
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

from robot.drivers.base import RobotDriver
from robot.drivers.serial.faults import FaultConfig, FaultStats, FaultyChannel
from robot.drivers.serial.frames import (
    PROTOCOL_VERSION,
    Ack,
    ArmSnapshot,
    Command,
    DoneEvent,
    EStop,
    Frame,
    FrameParser,
    GetLimits,
    GetState,
    Grip,
    Hello,
    HelloInfo,
    LimitsInfo,
    MoveJoints,
    MoveOutcome,
    Nak,
    Ping,
    QueryMove,
    Reset,
    Run,
    SetRate,
    StateEvent,
    Stop,
    TrajBegin,
    TrajPoint,
    encode,
)
from robot.drivers.serial.movetable import ExecutionRecord, MoveTable
from robot.drivers.serial.ptyport import PtyPort
from robot.errors import DriverError, RobotBusy
from robot.model import ASEA, ArmModel

__all__ = ["Emulator", "EmulatorStats", "ExecutionRecord", "FaultConfig", "run_emulator"]

log = logging.getLogger(__name__)

_MAX_RATE_HZ = 250.0


@dataclass
class EmulatorStats:
    """Counters of one emulator (mutable).

    Attributes
    ----------
    rx_frames : int
        Valid command frames received.
    rx_rejected : int
        Received lines dropped for a bad checksum or grammar.
    duplicates : int
        Commands whose sequence number was already known (answered from the cache or
        ignored while pending), hence not executed again.
    stale : int
        Commands refused as older than the duplicate window.
    executed : int
        Commands executed by the worker (the emergency stop not counted).
    events : int
        ``ST`` and ``DONE`` events sent.
    sessions : int
        Sessions opened (new session ids).
    watchdog_trips : int
        Moves stopped because the host fell silent.
    grips : int
        ``GRIP`` commands carried out (on and off).
    grips_holding : int
        ``GRIP 1`` answered with a part held (the vacuum switch made).
    grips_refused : int
        ``GRIP`` refused (emergency stop).
    faults : FaultStats
        Injected faults by kind.
    """

    rx_frames: int = 0
    rx_rejected: int = 0
    duplicates: int = 0
    stale: int = 0
    executed: int = 0
    events: int = 0
    sessions: int = 0
    watchdog_trips: int = 0
    grips: int = 0
    grips_holding: int = 0
    grips_refused: int = 0
    faults: FaultStats = field(default_factory=FaultStats)


class Emulator:
    """The controller side of the serial protocol, on a pseudo-terminal, backed by ``driver``.

    Parameters
    ----------
    driver : RobotDriver
        Executes the motion; it must be connected before :meth:`start` (``run_emulator``
        does it).  The emulator never closes it.
    fault : FaultConfig
        Faults to inject; can be replaced at any time through :attr:`fault`.
    link : str or path, optional
        Stable path where the pseudo-terminal's slave is published as a symlink (default: a
        fresh temporary directory).  Give this path to ``SerialDriver``.
    rate_hz : float
        Initial state-event rate (the host may change it with ``RATE``).
    baud : int, optional
        Model a real line by pacing bytes at this speed in both directions (a pseudo-terminal
        ignores baud rates); ``None`` (default) runs at memory speed.
    model : ArmModel
        Joint ranges the controller enforces and reports with ``LIMITS``.
    cache_depth : int
        Replies remembered per session for duplicate detection.
    window : int
        Commands the host may have unanswered at once (announced in ``HELLO``).
    max_points : int
        Largest trajectory accepted, in points.
    watchdog_s : float
        Host silence after which a running move is stopped (0 disables).
    start_tolerance_rad : float
        Largest distance between a trajectory's first point and the arm's position.
    name : str
        Controller name reported in ``HELLO``.
    seed : int, optional
        Seed of the fault injection's random numbers.
    """

    def __init__(
        self,
        driver: RobotDriver,
        *,
        fault: FaultConfig | None = None,
        link: str | None = None,
        rate_hz: float = 50.0,
        baud: int | None = None,
        model: ArmModel = ASEA,
        cache_depth: int = 64,
        window: int = 8,
        max_points: int = 10_000,
        watchdog_s: float = 1.0,
        start_tolerance_rad: float = 1e-3,
        name: str = "visioncell-emulator",
        seed: int | None = None,
    ) -> None:
        if not 0 <= rate_hz <= _MAX_RATE_HZ:
            raise ValueError(f"rate_hz must be in [0, {_MAX_RATE_HZ}], got {rate_hz!r}")
        if cache_depth < window + 1:
            raise ValueError(f"cache_depth must exceed window ({window}), got {cache_depth!r}")
        if window < 1 or max_points < 1 or watchdog_s < 0:
            raise ValueError(
                f"window, max_points must be >= 1 and watchdog_s >= 0, got "
                f"{window!r}, {max_points!r}, {watchdog_s!r}"
            )
        self.driver = driver
        self.fault = fault or FaultConfig()
        self.rate_hz = float(rate_hz)
        self.model = model
        self.cache_depth = int(cache_depth)
        self.window = int(window)
        self.max_points = int(max_points)
        self.watchdog_s = float(watchdog_s)
        self.name = name
        self.boot_id = secrets.token_hex(4).upper()
        self.stats = EmulatorStats()
        self.received: deque[Command] = deque(maxlen=4096)
        self.replies: deque[Ack | Nak] = deque(maxlen=4096)
        self._rng = random.Random(seed)
        self._port = PtyPort(self._on_rx_bytes, link=link)
        self._rx_wire = FaultyChannel(
            self._on_rx_wire, direction="rx", config=lambda: self.fault, rng=self._rng,
            stats=self.stats.faults, baud=baud,
        )  # fmt: skip
        self._tx_wire = FaultyChannel(
            self._port.write, direction="tx", config=lambda: self.fault, rng=self._rng,
            stats=self.stats.faults, baud=baud,
        )  # fmt: skip
        self._rx_partial = bytearray()
        self._parser = FrameParser(on_reject=self._on_reject)
        self._t0 = time.monotonic()
        self._session: str | None = None
        self._floor = 0
        self._max_seq = 0
        self._cache: dict[int, tuple[str, bytes] | None] = {}
        """Replies by sequence number, as (verb or NAK code, wire); None while executing."""
        self._estopped = False
        self._estops = 0  # emergency stops received (the worker checks it after a delay)
        self.moves = MoveTable(
            driver,
            model=model,
            max_points=self.max_points,
            start_tolerance_rad=float(start_tolerance_rad),
            estopped=lambda: self._estopped,
            on_done=self._on_move_done,
            watchdog_s=self.watchdog_s,
        )
        self.executions = self.moves.executions
        """Every motion handed to the backing driver, in order (:class:`ExecutionRecord`)."""
        self._eseq = 0
        self._last_rx = 0.0
        self._queue: asyncio.Queue[Command] = asyncio.Queue()
        self._tasks: list[asyncio.Task[None]] = []
        self._aux: set[asyncio.Task[None]] = set()
        self._vanish_task: asyncio.Task[None] | None = None

    # -- lifecycle ----------------------------------------------------------------------------
    @property
    def path(self) -> str:
        """The stable device path to give the host (a symlink to the current slave)."""
        return self._port.path

    async def start(self) -> str:
        """Create the pseudo-terminal, start serving; returns :attr:`path`."""
        self._port.reopen()
        if not self._tasks:
            for coro, name in (
                (self._worker(), "emulator-worker"),
                (self._stream(), "emulator-stream"),
                (self._watchdog(), "emulator-watchdog"),
            ):
                self._tasks.append(asyncio.create_task(coro, name=name))
        return self.path

    async def close(self) -> None:
        """Stop serving and remove the port (the backing driver stays as it is)."""
        tasks = [*self._tasks, *self._aux, *([self._vanish_task] if self._vanish_task else [])]
        for t in tasks:
            t.cancel()
        for t in tasks:
            with contextlib.suppress(asyncio.CancelledError):
                await t
        self._tasks.clear()
        await self.moves.close()
        await self._rx_wire.close()
        await self._tx_wire.close()
        self._port.close()

    async def __aenter__(self) -> Emulator:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    async def vanish(self, seconds: float) -> None:
        """Make the port disappear for ``seconds``, then re-create it at the same path."""
        if not seconds >= 0:
            raise ValueError(f"seconds must be >= 0, got {seconds!r}")
        self._port.vanish()
        self._rx_wire.clear()
        self._tx_wire.clear()
        self._rx_partial.clear()
        self._parser.clear()
        await asyncio.sleep(seconds)
        self._port.reopen()

    @property
    def port_open(self) -> bool:
        """False while the port has vanished."""
        return self._port.is_open

    def executed_mids(self, session: str | None = None) -> list[int]:
        """Move ids handed to the backing driver, in order (of ``session`` if given)."""
        return [e.mid for e in self.executions if session is None or e.session == session]

    # -- receive path -------------------------------------------------------------------------
    def _on_rx_bytes(self, data: bytes) -> None:
        self._rx_partial += data
        while True:
            i = self._rx_partial.find(b"\n")
            if i < 0:
                break
            line = bytes(self._rx_partial[: i + 1])
            del self._rx_partial[: i + 1]
            self._rx_wire.push(line, carries_command=True)
            cfg = self.fault
            if cfg.vanish_p and self._vanish_task is None and self._rng.random() < cfg.vanish_p:
                self.stats.faults.vanish += 1
                self.stats.faults.on_commands += 1
                self._vanish_task = asyncio.create_task(self._vanish_once(cfg.vanish_s))
                return
        if len(self._rx_partial) > 4096:  # no LF for ages: hand it on, the parser drops it
            self._rx_wire.push(bytes(self._rx_partial), carries_command=False)
            self._rx_partial.clear()

    async def _vanish_once(self, seconds: float) -> None:
        try:
            await self.vanish(seconds)
        finally:
            self._vanish_task = None

    def _on_rx_wire(self, data: bytes) -> None:
        for frame in self._parser.feed(data):
            self._on_frame(frame)

    def _on_reject(self, exc: Exception) -> None:
        self.stats.rx_rejected += 1
        seq = getattr(exc, "seq", None)
        if seq is not None and not self.fault.silent:
            self._send(Nak(seq, "SYNTAX", str(exc)))

    def _on_frame(self, frame: Frame) -> None:
        if self.fault.silent or not isinstance(frame, Command):
            return
        self.stats.rx_frames += 1
        self.received.append(frame)
        self._last_rx = time.monotonic()
        if isinstance(frame, Hello):
            self._send(self._hello(frame))
            return
        if self._session is None:
            if isinstance(frame, EStop):  # an emergency stop is obeyed in every state
                self._emergency_stop(frame)
            else:
                self._send(Nak(frame.seq, "NOSESSION", "send HELLO first"))
            return
        seq = frame.seq
        if seq in self._cache:
            self.stats.duplicates += 1
            cached = self._cache[seq]
            if cached is not None and not self._muted(cached[0]):
                self._tx_wire.push(cached[1], carries_command=True)
            return  # still being executed: its one reply will follow
        if seq <= max(self._floor, self._max_seq - self.cache_depth):
            self.stats.stale += 1
            self._send(Nak(seq, "STALE", f"seq {seq} is outside the duplicate window"))
            return
        self._cache[seq] = None
        self._max_seq = max(self._max_seq, seq)
        if len(self._cache) > self.cache_depth:
            low = max(self._floor, self._max_seq - self.cache_depth)
            for k in [k for k in self._cache if k <= low]:
                del self._cache[k]
        if isinstance(frame, EStop):
            self._emergency_stop(frame)
        elif self._queue.qsize() >= self.window + 1:
            self._finish(seq, Nak(seq, "FULL", f"more than {self.window} commands unanswered"))
        else:
            self._queue.put_nowait(frame)

    def _hello(self, cmd: Hello) -> Ack | Nak:
        if cmd.version != PROTOCOL_VERSION:
            return Nak(cmd.seq, "VERSION", f"speak version {PROTOCOL_VERSION}")
        resumed = cmd.session == self._session
        if not resumed:
            self._session = cmd.session
            self.stats.sessions += 1
            self._cache.clear()
            self.moves.new_session(cmd.session)
            self._floor = self._max_seq = cmd.seq
        else:
            self._max_seq = max(self._max_seq, cmd.seq)
        info = HelloInfo(
            PROTOCOL_VERSION, self.boot_id, resumed, self.cache_depth, self.window,
            self.max_points, self.rate_hz, self.name,
        )  # fmt: skip
        return Ack(cmd.seq, "HELLO", tuple(info.to_args()))

    def _emergency_stop(self, cmd: EStop) -> None:
        self._estopped = True
        self._estops += 1
        flushed: list[Command] = []
        while not self._queue.empty():
            flushed.append(self._queue.get_nowait())
        self.moves.discard_loading("emergency stop")

        async def act() -> None:
            await self.driver.estop()
            self._finish(cmd.seq, Ack(cmd.seq, "ESTOP"))
            for c in flushed:
                self._finish(c.seq, Nak(c.seq, "ESTOP", "flushed by an emergency stop"))

        task = asyncio.create_task(act(), name="emulator-estop")
        self._aux.add(task)
        task.add_done_callback(self._aux.discard)

    def _finish(self, seq: int, reply: Ack | Nak) -> None:
        wire = encode(reply)
        tag = reply.verb if isinstance(reply, Ack) else reply.code
        if seq in self._cache:
            self._cache[seq] = (tag, wire)
        self.replies.append(reply)
        if not self._muted(tag):
            self._tx_wire.push(wire, carries_command=True)

    def _muted(self, tag: str) -> bool:
        """True if replies tagged ``tag`` are lost on the line (``FaultConfig.mute_replies``)."""
        return tag in self.fault.mute_replies

    def _send(self, frame: Frame) -> None:
        if isinstance(frame, Ack | Nak):
            self.replies.append(frame)
            if self._muted(frame.verb if isinstance(frame, Ack) else frame.code):
                return
        self._tx_wire.push(encode(frame), carries_command=not isinstance(frame, StateEvent))

    # -- command execution --------------------------------------------------------------------
    async def _worker(self) -> None:
        while True:
            cmd = await self._queue.get()
            if self.fault.process_delay_s:
                estops = self._estops
                await asyncio.sleep(self.fault.process_delay_s)
                if self._estops != estops:  # still waiting when the stop came: flushed too
                    self._finish(cmd.seq, Nak(cmd.seq, "ESTOP", "flushed by an emergency stop"))
                    continue
            try:
                reply = await self._execute(cmd)
            except Exception as exc:  # the backing driver failed: report, keep serving
                log.exception("emulator: %s failed", cmd.VERB)
                reply = Nak(cmd.seq, "FAULT", f"{type(exc).__name__}: {exc}")
            self.stats.executed += 1
            self._finish(cmd.seq, reply)

    async def _execute(self, cmd: Command) -> Ack | Nak:
        seq = cmd.seq
        if isinstance(cmd, Ping):
            return Ack(seq, "PING", (str(self._ms()),))
        if isinstance(cmd, GetState):
            return Ack(seq, "STATE", tuple(self._snapshot().to_args()))
        if isinstance(cmd, GetLimits):
            m = self.model
            info = LimitsInfo(tuple(m.lower), tuple(m.upper), tuple(m.max_velocity_rad_s))
            return Ack(seq, "LIMITS", tuple(info.to_args()))
        if isinstance(cmd, SetRate):
            if not 0 <= cmd.rate_hz <= _MAX_RATE_HZ:
                return Nak(seq, "SYNTAX", f"rate must be in [0, {_MAX_RATE_HZ:g}] Hz")
            self.rate_hz = cmd.rate_hz
            return Ack(seq, "RATE", (SetRate(0, self.rate_hz).args()[0],))
        if isinstance(cmd, Stop):
            await self.driver.stop()
            return Ack(seq, "STOP")
        if isinstance(cmd, Reset):
            await self.driver.reset()
            self._estopped = False
            return Ack(seq, "RESET")
        if isinstance(cmd, QueryMove | TrajBegin | TrajPoint | Run | MoveJoints):
            return self.moves.handle(cmd)
        if isinstance(cmd, Grip):
            return await self._grip(cmd)
        return Nak(seq, "SYNTAX", f"{cmd.VERB} not handled here")

    async def _grip(self, cmd: Grip) -> Ack | Nak:
        """Suction on/off, passed to the backing driver (its own book-keeping, or the
        simulator's suction cup); refused during an emergency stop."""
        if self._estopped:
            self.stats.grips_refused += 1
            return Nak(cmd.seq, "ESTOP", "emergency stop active: the gripper keeps its state")
        try:
            report = await self.driver.grip(cmd.on)
        except (RobotBusy, DriverError) as exc:
            self.stats.grips_refused += 1
            return Nak(cmd.seq, "ESTOP", str(exc))
        self.stats.grips += 1
        self.stats.grips_holding += int(bool(cmd.on and report.holding))
        return Ack(cmd.seq, "GRIP", ("1" if report.on else "0", "1" if report.holding else "0"))

    def _on_move_done(self, session: str, outcome: MoveOutcome) -> None:
        if session == self._session:
            self._eseq += 1
            self.stats.events += 1
            self._send(DoneEvent(self._eseq, outcome))

    # -- state stream and watchdog ------------------------------------------------------------
    def _ms(self) -> int:
        return int((time.monotonic() - self._t0) * 1000)

    def _snapshot(self) -> ArmSnapshot:
        st = self.driver.state
        mid, status = self.moves.latest()
        return ArmSnapshot(
            stamp_ms=self._ms(),
            q=tuple(st.q),
            qd=tuple(st.qd),
            moving=st.moving or self.moves.moving,
            estopped=self._estopped or st.estopped,
            mid=mid,
            move_status=status,
            fault=st.fault,
            gripper_on=st.gripper_on,
            holding=st.holding,
        )

    def _host_alive(self) -> bool:
        return self.watchdog_s == 0 or time.monotonic() - self._last_rx < self.watchdog_s

    async def _stream(self) -> None:
        loop = asyncio.get_running_loop()
        next_t = loop.time()
        while True:
            period = 1.0 / self.rate_hz if self.rate_hz > 0 else 0.05
            next_t += period
            now = loop.time()
            if next_t < now - period:  # fell behind (a busy loop): do not burst to catch up
                next_t = now
            await asyncio.sleep(max(0.0, next_t - now))
            if self.rate_hz > 0 and self._session is not None and self._host_alive():
                self._eseq += 1
                self.stats.events += 1
                self._send(StateEvent(self._eseq, self._snapshot()))

    async def _watchdog(self) -> None:
        while True:
            await asyncio.sleep(0.02)
            if not self.watchdog_s or self._host_alive():
                continue
            mid = self.moves.trip_watchdog()
            if mid is not None:
                self.stats.watchdog_trips += 1
                log.warning(
                    "emulator: host silent for %.2f s, stopping move %d", self.watchdog_s, mid
                )
                await self.driver.stop()


async def run_emulator(
    driver: RobotDriver,
    *,
    link: str | None = None,
    rate_hz: float = 50.0,
    baud: int | None = None,
    fault: FaultConfig | None = None,
    seed: int | None = None,
    announce: Callable[[str], None] = print,
    stop: asyncio.Event | None = None,
) -> Emulator:
    """Serve the controller protocol for ``driver`` until ``stop`` is set (or cancelled).

    Connects ``driver``, starts an :class:`Emulator`, calls ``announce`` with the device path
    (the line ``visioncell emulator`` prints), waits, then closes the emulator and the
    driver.  This is the entry point behind ``visioncell emulator``.

    Parameters
    ----------
    driver : RobotDriver
        Backing arm (``IdealDriver()`` or the simulator's driver).
    link : str, optional
        Stable path for the port, e.g. ``var/robot-tty`` (default: a temporary directory).
    rate_hz, baud, fault, seed
        As for :class:`Emulator`.
    announce : callable
        Receives the device path once the port exists (default: ``print``).
    stop : asyncio.Event, optional
        Set it to shut down; without one, runs until the task is cancelled.

    Returns
    -------
    Emulator
        The closed emulator (its ``stats`` and ``executions`` stay readable).
    """
    await driver.connect()
    emu = Emulator(driver, fault=fault, link=link, rate_hz=rate_hz, baud=baud, seed=seed)
    try:
        announce(await emu.start())
        await (stop.wait() if stop is not None else asyncio.Event().wait())
    finally:
        await emu.close()
        await driver.close()
    return emu


def main(argv: list[str] | None = None) -> int:
    """``python -m robot.drivers.serial.emulator``: serve an ideal arm until interrupted.

    Prints the device path on its own line first.  The backend's ``visioncell emulator``
    command offers the same options (and ``--driver sim`` for the simulator).
    """
    import argparse
    import signal

    from robot.drivers.ideal import IdealDriver

    ap = argparse.ArgumentParser(
        prog="python -m robot.drivers.serial.emulator", description=main.__doc__
    )
    ap.add_argument("--link", help="stable device path to create (default: a temporary one)")
    ap.add_argument("--rate", type=float, default=50.0, help="state events per second")
    ap.add_argument("--baud", type=int, default=None, help="pace bytes as on a real line")
    ap.add_argument("--time-scale", type=float, default=1.0, help="arm seconds per second")
    ap.add_argument("--seed", type=int, default=None)
    for knob, kind in (("drop", "p"), ("corrupt", "p"), ("truncate", "p"), ("garbage", "p"),
                       ("delay", "p"), ("delay-s", "s"), ("vanish", "p"), ("vanish-s", "s")):  # fmt: skip
        ap.add_argument(f"--fault-{knob}", type=float, default=None, help=f"FaultConfig {kind}")
    args = ap.parse_args(argv)
    names = {"drop": "drop_p", "corrupt": "corrupt_p", "truncate": "truncate_p",
             "garbage": "garbage_p", "delay": "delay_p", "delay_s": "delay_s",
             "vanish": "vanish_p", "vanish_s": "vanish_s"}  # fmt: skip
    given = {
        field_: getattr(args, f"fault_{opt}")
        for opt, field_ in names.items()
        if getattr(args, f"fault_{opt}") is not None
    }
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")

    def announce(path: str) -> None:
        print(path, flush=True)

    async def serve() -> None:
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):  # clean exit: the link is removed
            loop.add_signal_handler(sig, stop.set)
        await run_emulator(
            IdealDriver(time_scale=args.time_scale, rate_hz=max(50.0, args.rate)),
            link=args.link,
            rate_hz=args.rate,
            baud=args.baud,
            fault=FaultConfig(**given),
            seed=args.seed,
            announce=announce,
            stop=stop,
        )

    asyncio.run(serve())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
