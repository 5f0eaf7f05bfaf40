"""What the read cache (:mod:`backend.readcache`) and the sign-in cache
(:mod:`backend.caches`) share: the check of their size and TTL, and one read per key at a
time (callers that miss while a read of their key is in flight share it)."""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable, Hashable
from dataclasses import dataclass
from typing import Any, TypeVar, cast

__all__ = ["Flights", "check_limits"]

T = TypeVar("T")


def check_limits(ttl_s: float, max_entries: int, max_ttl_s: float) -> None:
    """Refuse a TTL outside ``0..max_ttl_s`` seconds or a size outside 1..1000000 entries."""
    if isinstance(ttl_s, bool) or not isinstance(ttl_s, int | float):
        raise TypeError(f"ttl_s must be a number, got {ttl_s!r}")
    if not 0.0 <= float(ttl_s) <= max_ttl_s:
        raise ValueError(f"ttl_s must be within 0..{max_ttl_s:g} s, got {ttl_s!r}")
    if isinstance(max_entries, bool) or not isinstance(max_entries, int):
        raise TypeError(f"max_entries must be an int, got {max_entries!r}")
    if not 1 <= max_entries <= 1_000_000:
        raise ValueError(f"max_entries must be within 1..1000000, got {max_entries!r}")


@dataclass(frozen=True)
class _Flight:
    loop: asyncio.AbstractEventLoop
    tag: Any
    future: asyncio.Future[Any]


class Flights:
    """One read per key at a time: callers that miss while a read of their key is in
    flight share its answer (or its error), when ``may_share`` accepts its ``tag``; a
    caller whose reader went away (cancelled) reads itself."""

    def __init__(self) -> None:
        self._flights: dict[Hashable, _Flight] = {}
        #: Callers that shared a read in flight.
        self.shared = 0

    async def read(
        self, key: Hashable, tag: Any, may_share: Callable[[Any], bool],
        read: Callable[[], Awaitable[T]],
    ) -> T:  # fmt: skip
        """``await read()`` for ``key``, or the answer of the read of ``key`` in flight on
        this loop when ``may_share`` accepts that read's tag."""
        loop = asyncio.get_running_loop()
        flight = self._flights.get(key)
        if flight is not None and flight.loop is loop and may_share(flight.tag):
            self.shared += 1
            try:
                return cast(T, await asyncio.shield(flight.future))
            except asyncio.CancelledError:
                if not flight.future.cancelled():
                    raise  # this caller was cancelled, not the read it waited for
        mine = _Flight(loop, tag, loop.create_future())
        self._flights[key] = mine
        try:
            value = await read()
        except asyncio.CancelledError:
            mine.future.cancel()
            raise
        except BaseException as exc:
            mine.future.set_exception(exc)
            mine.future.exception()  # marked retrieved: its waiters, if any, get it too
            raise
        finally:
            if self._flights.get(key) is mine:
                del self._flights[key]
        mine.future.set_result(value)
        return value

    def clear(self) -> None:
        """Forget the reads in flight (their callers still get their answers)."""
        self._flights.clear()
