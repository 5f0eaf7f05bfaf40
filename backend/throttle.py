"""Throttling of failed sign-ins, per client address.

Every request that presents a bad, expired or revoked token (a REST bearer token, the
first message of the console's WebSocket, a token typed into the 3D view's panel) counts
one failure against the client's address.  After ``max_failures`` failures within
``window_s`` seconds the address is blocked for ``block_s`` seconds: every sign-in from it,
even with a correct token, is refused with 429 and ``Retry-After`` until the block ends.

Memory is bounded: at most ``max_clients`` addresses are tracked, the least recently seen
one is forgotten first, and each address keeps at most ``max_failures`` timestamps.
"""

from __future__ import annotations

import math
import threading
import time
from collections import OrderedDict, deque
from collections.abc import Callable
from dataclasses import dataclass, field

__all__ = ["SignInThrottle", "TooManyAttempts"]


class TooManyAttempts(Exception):
    """Sign-in refused: the client failed too often; retry after ``retry_after_s`` seconds."""

    def __init__(self, retry_after_s: float) -> None:
        self.retry_after_s = max(1, math.ceil(retry_after_s))
        super().__init__(
            f"too many failed sign-ins from this address: try again in {self.retry_after_s} s"
        )


@dataclass
class _Client:
    failures: deque[float] = field(default_factory=deque)
    blocked_until: float = 0.0


class SignInThrottle:
    """Failed sign-ins per client address (thread-safe: the 3D view calls it too).

    Parameters
    ----------
    max_failures : int
        Failures within ``window_s`` that block the address (>= 1).
    window_s : float
        Sliding window over which failures are counted, seconds (> 0).
    block_s : float
        How long a blocked address stays blocked, seconds (> 0).
    max_clients : int
        Most addresses tracked at once (>= 1); the least recently seen is dropped first.
    clock : callable, optional
        Monotonic time in seconds (tests pass their own).
    """

    def __init__(
        self,
        *,
        max_failures: int = 5,
        window_s: float = 60.0,
        block_s: float = 60.0,
        max_clients: int = 10_000,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if isinstance(max_failures, bool) or not isinstance(max_failures, int) or max_failures < 1:
            raise ValueError(f"max_failures must be an integer >= 1, got {max_failures!r}")
        for name, v in (("window_s", window_s), ("block_s", block_s)):
            if isinstance(v, bool) or not math.isfinite(float(v)) or float(v) <= 0:
                raise ValueError(f"{name} must be a finite number of seconds > 0, got {v!r}")
        if isinstance(max_clients, bool) or not isinstance(max_clients, int) or max_clients < 1:
            raise ValueError(f"max_clients must be an integer >= 1, got {max_clients!r}")
        self.max_failures = max_failures
        self.window_s = float(window_s)
        self.block_s = float(block_s)
        self.max_clients = max_clients
        self._clock = clock
        self._clients: OrderedDict[str, _Client] = OrderedDict()
        self._lock = threading.Lock()

    def __len__(self) -> int:
        """Number of addresses tracked now."""
        return len(self._clients)

    def check(self, client: str) -> None:
        """Raise :class:`TooManyAttempts` if ``client`` is blocked now."""
        now = self._clock()
        with self._lock:
            entry = self._clients.get(client)
            if entry is None:
                return
            if entry.blocked_until > now:
                raise TooManyAttempts(entry.blocked_until - now)

    def failure(self, client: str) -> None:
        """Count one failed sign-in from ``client`` (may block it)."""
        now = self._clock()
        with self._lock:
            entry = self._clients.pop(client, None) or _Client()
            self._clients[client] = entry  # most recently seen last
            while entry.failures and entry.failures[0] <= now - self.window_s:
                entry.failures.popleft()
            entry.failures.append(now)
            if len(entry.failures) >= self.max_failures:
                entry.blocked_until = now + self.block_s
                entry.failures.clear()
            while len(self._clients) > self.max_clients:
                self._clients.popitem(last=False)
            self._expire(now)

    def _expire(self, now: float) -> None:
        # Drop a few stale entries from the old end (bounded work per call).
        for _ in range(8):
            if not self._clients:
                return
            key, entry = next(iter(self._clients.items()))
            newest = entry.failures[-1] if entry.failures else 0.0
            if entry.blocked_until <= now and newest <= now - self.window_s:
                del self._clients[key]
            else:
                return
