"""A stopwatch timing an inspection's stages on an injectable clock.

Each stage is timed by :meth:`Stopwatch.stage`; a stage opened inside another pauses the
outer one, so every second is counted in exactly one stage.  :meth:`Stopwatch.pause` stops
the running stage without timing anything (motion the cell times itself, credited with
:meth:`Stopwatch.add`).  Times measured elsewhere (the cell's move, settle and acquire, the
recognition's own timings) are added with :meth:`Stopwatch.add`, or moved out of the
running stage with :meth:`Stopwatch.credit`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager, contextmanager

__all__ = ["Stopwatch"]


class Stopwatch:
    """Seconds per stage (``durations``, rounded to 0.1 ms as stored)."""

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self.clock = clock
        self.durations: dict[str, float] = {}
        #: The open stages, innermost last: (name, None while paused) and when each
        #: started counting.
        self._names: list[str | None] = []
        self._since: list[float] = []

    def add(self, name: str, seconds: float) -> None:
        """Count ``seconds`` (measured elsewhere) in stage ``name``."""
        self.durations[name] = round(self.durations.get(name, 0.0) + float(seconds), 4)

    def credit(self, name: str, seconds: float) -> None:
        """Move ``seconds`` of the running stage's time (part of it, timed by the work it
        ran) to stage ``name``."""
        if self._names and self._names[-1] is not None:
            self._since[-1] += float(seconds)
        self.add(name, seconds)

    def _count_top(self, now: float) -> None:
        name = self._names[-1]
        if name is not None:
            self.add(name, max(0.0, now - self._since[-1]))
        self._since[-1] = now

    @contextmanager
    def stage(self, name: str | None) -> Iterator[None]:
        """Time the block as stage ``name`` (None: pause, time nothing), pausing the stage
        it is opened in."""
        now = self.clock()
        if self._names:
            self._count_top(now)
        self._names.append(name)
        self._since.append(now)
        try:
            yield
        finally:
            now = self.clock()
            self._count_top(now)
            self._names.pop()
            self._since.pop()
            if self._since:
                self._since[-1] = now

    def pause(self) -> AbstractContextManager[None]:
        """Stop the running stage for the block without timing it."""
        return self.stage(None)

    def restart(self, at: float) -> None:
        """Count the running stage from ``at`` (a clock reading) instead, dropping what it
        counted before: a search's time before its part came is no inspection's."""
        if self._names:
            self._since[-1] = at
            name = self._names[-1]
            if name is not None:
                self.durations.pop(name, None)
