"""Fault injection and wire pacing for the controller emulator.

:class:`FaultConfig` says what goes wrong on the line; :class:`FaultyChannel` applies it to
one direction of the wire, line by line, and then delivers the bytes in order, optionally
paced at a baud rate.  A pseudo-terminal moves bytes as fast as memory does and ignores the
baud rate the host sets, so pacing (``baud``) is the only way to model the time a real
115,200 baud line takes: 10 bit times per byte (8N1), i.e. 86.8 microseconds per byte.
"""

from __future__ import annotations

import asyncio
import contextlib
import random
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, fields

__all__ = ["FaultConfig", "FaultStats", "FaultyChannel"]

_DIRECTIONS = ("both", "rx", "tx")


@dataclass(frozen=True)
class FaultConfig:
    """What goes wrong on the emulated line.  Probabilities are per line (frame).

    Attributes
    ----------
    drop_p : float
        A line vanishes whole.
    corrupt_p : float
        One byte of a line is replaced by a different random byte (the checksum catches it).
    truncate_p : float
        A line loses its tail, LF included, so it runs into the next line (partial lines).
    garbage_p : float
        A burst of 1-64 random bytes is inserted before a line (half the time ended by LF).
    delay_p, delay_s : float
        A line, and everything behind it, is held back ``delay_s`` seconds.
    vanish_p, vanish_s : float
        After a received command line, the port disappears for ``vanish_s`` seconds.
    silent : bool
        The controller ignores everything it receives (a hung controller; for timeouts).
    process_delay_s : float
        Time the controller spends on every command before answering (a slow controller);
        the emergency stop is exempt, as it is handled in the receive path.
    directions : str
        ``"both"``, ``"rx"`` (host to controller only) or ``"tx"`` (controller to host only)
        for the per-line faults.
    mute_replies : tuple of str
        Verbs (``"RATE"``, ``"HELLO"``, ...) whose replies never reach the host: the
        controller executes the command, but its answer, and every answer to a re-send, is
        lost on the line (a targeted fault, e.g. during the host's handshake).
    """

    drop_p: float = 0.0
    corrupt_p: float = 0.0
    truncate_p: float = 0.0
    garbage_p: float = 0.0
    delay_p: float = 0.0
    delay_s: float = 0.05
    vanish_p: float = 0.0
    vanish_s: float = 0.5
    silent: bool = False
    process_delay_s: float = 0.0
    directions: str = "both"
    mute_replies: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        for name in ("drop_p", "corrupt_p", "truncate_p", "garbage_p", "delay_p", "vanish_p"):
            v = getattr(self, name)
            if not 0.0 <= v <= 1.0:
                raise ValueError(f"{name} must be a probability in [0, 1], got {v!r}")
        for name in ("delay_s", "vanish_s", "process_delay_s"):
            v = getattr(self, name)
            if not 0.0 <= v < 3600.0:
                raise ValueError(f"{name} must be in [0, 3600) seconds, got {v!r}")
        if self.directions not in _DIRECTIONS:
            raise ValueError(f"directions must be one of {_DIRECTIONS}, got {self.directions!r}")
        if not isinstance(self.mute_replies, tuple) or not all(
            isinstance(v, str) and v.isalpha() and v.isupper() for v in self.mute_replies
        ):
            raise ValueError(
                f"mute_replies must be a tuple of upper-case verbs, got {self.mute_replies!r}"
            )

    def applies_to(self, direction: str) -> bool:
        """True if per-line faults hit ``direction`` (``"rx"`` or ``"tx"``)."""
        return self.directions in ("both", direction)


@dataclass
class FaultStats:
    """How many faults were injected, by kind (mutable counters).

    ``on_commands`` counts lines carrying a command or its reply that were hit by at least
    one fault (state events excluded); ``total`` sums every injected fault.
    """

    drop: int = 0
    corrupt: int = 0
    truncate: int = 0
    garbage: int = 0
    delay: int = 0
    vanish: int = 0
    on_commands: int = 0

    @property
    def total(self) -> int:
        """All injected faults of every kind."""
        return self.drop + self.corrupt + self.truncate + self.garbage + self.delay + self.vanish

    def as_dict(self) -> dict[str, int]:
        """Counters as a plain dict, with ``total``."""
        return {f.name: getattr(self, f.name) for f in fields(self)} | {"total": self.total}


class FaultyChannel:
    """One direction of the emulated wire: faults, then in-order (optionally paced) delivery.

    Parameters
    ----------
    deliver : callable
        Receives the bytes at the far end of the wire.
    direction : str
        ``"rx"`` (host to controller) or ``"tx"`` (controller to host).
    config : callable
        Returns the current :class:`FaultConfig` (read at every line, so it can change).
    rng : random.Random
        Source of randomness (seed it for repeatable campaigns).
    stats : FaultStats
        Counters to update.
    baud : int, optional
        Pace delivery at this line speed (10 bits per byte); ``None`` delivers at once.
    """

    def __init__(
        self,
        deliver: Callable[[bytes], None],
        *,
        direction: str,
        config: Callable[[], FaultConfig],
        rng: random.Random,
        stats: FaultStats,
        baud: int | None = None,
    ) -> None:
        if direction not in ("rx", "tx"):
            raise ValueError(f"direction must be 'rx' or 'tx', got {direction!r}")
        if baud is not None and baud <= 0:
            raise ValueError(f"baud must be positive, got {baud!r}")
        self._deliver = deliver
        self.direction = direction
        self._config = config
        self._rng = rng
        self.stats = stats
        self._byte_s = 0.0 if baud is None else 10.0 / baud
        self._queue: deque[tuple[float, bytes]] = deque()
        self._free_at = 0.0
        self._pump: asyncio.Task[None] | None = None

    def push(self, line: bytes, *, carries_command: bool) -> None:
        """Send one line (LF included) through the faults and down the wire."""
        cfg = self._config()
        rng = self._rng
        delay = 0.0
        hit = False
        if cfg.applies_to(self.direction):
            if rng.random() < cfg.drop_p:
                self.stats.drop += 1
                if carries_command:
                    self.stats.on_commands += 1
                return
            if rng.random() < cfg.corrupt_p:
                i = rng.randrange(len(line))
                line = line[:i] + bytes([(line[i] + rng.randrange(1, 256)) % 256]) + line[i + 1 :]
                self.stats.corrupt += 1
                hit = True
            if len(line) > 1 and rng.random() < cfg.truncate_p:
                line = line[: rng.randrange(1, len(line))]
                self.stats.truncate += 1
                hit = True
            if rng.random() < cfg.garbage_p:
                burst = bytes(rng.randrange(256) for _ in range(rng.randint(1, 64)))
                line = burst + (b"\n" if rng.random() < 0.5 else b"") + line
                self.stats.garbage += 1
                hit = True
            if rng.random() < cfg.delay_p:
                delay = cfg.delay_s
                self.stats.delay += 1
                hit = True
        if hit and carries_command:
            self.stats.on_commands += 1
        self._send(line, delay)

    def _send(self, data: bytes, delay: float) -> None:
        loop = asyncio.get_running_loop()
        now = loop.time()
        if delay == 0.0 and self._byte_s == 0.0 and not self._queue:
            self._deliver(data)
            return
        # Bytes cannot overtake each other on a wire: a held line holds those behind it.
        at = max(now + delay, self._free_at) + len(data) * self._byte_s
        self._free_at = at
        self._queue.append((at, data))
        if self._pump is None or self._pump.done():
            self._pump = asyncio.create_task(self._run(), name=f"wire-{self.direction}")

    async def _run(self) -> None:
        loop = asyncio.get_running_loop()
        while self._queue:
            at, data = self._queue[0]
            wait = at - loop.time()
            if wait > 0:
                await asyncio.sleep(wait)
            if self._queue and self._queue[0][1] is data:
                self._queue.popleft()
                self._deliver(data)

    def clear(self) -> None:
        """Forget bytes still on the wire (the port vanished)."""
        self._queue.clear()
        self._free_at = 0.0

    async def close(self) -> None:
        """Stop delivering."""
        self.clear()
        if self._pump is not None:
            self._pump.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._pump
            self._pump = None
