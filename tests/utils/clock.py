"""A clock that moves only when the test moves it, for caches and deadlines under test."""

from __future__ import annotations

import time

__all__ = ["SteppedClock"]


class SteppedClock:
    """Monotonic seconds that change only by :meth:`advance` (or by setting :attr:`now`).

    Call it (``clock()``) where a component takes a ``clock``; its :meth:`monotonic` makes
    it a stand-in for a module's ``time`` too.  A test process stalled by a busy machine
    then sees the same ages and expiries as on an idle one.
    """

    def __init__(self, start: float | None = None) -> None:
        # from the real clock's reading: a stand-in swapped in for a running component's
        # clock carries on from what its entries were stamped with
        self.now = time.monotonic() if start is None else float(start)

    def __call__(self) -> float:
        return self.now

    def monotonic(self) -> float:
        return self.now

    def advance(self, seconds: float) -> float:
        """Move forward by ``seconds`` (>= 0); returns the new time."""
        if not seconds >= 0.0:
            raise ValueError(f"a monotonic clock only moves forward, got {seconds!r}")
        self.now += float(seconds)
        return self.now
