"""Exponential backoff with jitter, shared by every supervised loop that retries.

The camera supervisor (``backend.cell.camera``) and the serial link supervisor
(``robot.drivers.serial.supervisor``) wait between attempts with one :class:`Backoff`:
the delay starts at ``initial_s``, is multiplied by ``factor`` after each failure up to
``max_s``, and each actual wait is the delay times a random factor drawn uniformly from
``jitter`` (so that the cells of a plant that lost the same network do not retry in lock
step).  A success calls :meth:`Backoff.reset`.

Example
-------
>>> b = Backoff(initial_s=0.5, max_s=4.0, rng=random.Random(0))
>>> [round(b.next_delay(), 3) for _ in range(5)]  # doctest: +SKIP
"""

from __future__ import annotations

import asyncio
import math
import random

__all__ = ["Backoff"]


class Backoff:
    """Delays for retrying: ``initial_s * factor**k`` capped at ``max_s``, times jitter.

    Parameters
    ----------
    initial_s : float
        First delay, seconds (> 0).
    max_s : float
        Largest delay before jitter, seconds (>= ``initial_s``).
    factor : float
        Growth per failure (>= 1).
    jitter : tuple of float
        ``(low, high)`` bounds of the random factor applied to each wait, ``0 < low <= high``.
    rng : random.Random, optional
        Source of the jitter (seed it in tests).
    """

    def __init__(
        self,
        *,
        initial_s: float = 0.5,
        max_s: float = 10.0,
        factor: float = 2.0,
        jitter: tuple[float, float] = (0.5, 1.0),
        rng: random.Random | None = None,
    ) -> None:
        for name, v in (("initial_s", initial_s), ("max_s", max_s), ("factor", factor)):
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                raise ValueError(f"{name} must be a finite number, got {v!r}")
        if not 0.0 < initial_s <= 3600.0:
            raise ValueError(f"initial_s must be in (0, 3600] s, got {initial_s!r}")
        if not initial_s <= max_s <= 3600.0:
            raise ValueError(f"max_s must be in [initial_s, 3600] s, got {max_s!r}")
        if not 1.0 <= factor <= 10.0:
            raise ValueError(f"factor must be in [1, 10], got {factor!r}")
        lo, hi = jitter
        if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 < lo <= hi <= 2.0):
            raise ValueError(f"jitter must satisfy 0 < low <= high <= 2, got {jitter!r}")
        self.initial_s = float(initial_s)
        self.max_s = float(max_s)
        self.factor = float(factor)
        self.jitter = (float(lo), float(hi))
        self._rng = rng or random.Random()
        self._delay = self.initial_s
        self.attempts = 0
        """Failures since the last :meth:`reset`."""

    def next_delay(self) -> float:
        """The jittered wait before the next attempt (seconds); grows the delay."""
        wait = self._delay * self._rng.uniform(*self.jitter)
        self._delay = min(self._delay * self.factor, self.max_s)
        self.attempts += 1
        return wait

    async def sleep(self) -> float:
        """Wait :meth:`next_delay` seconds; returns the wait."""
        wait = self.next_delay()
        await asyncio.sleep(wait)
        return wait

    def reset(self) -> None:
        """After a success: the next delay is ``initial_s`` again."""
        self._delay = self.initial_s
        self.attempts = 0
