"""The console's hot reads, kept for a moment: :class:`ReadCache`.

A :class:`cachetools.TTLCache` (bounded, least recently used first out, entries expire
after a TTL counted by an injectable clock), kept correct by explicit invalidation, not by
watching the database:

- the services that write call :func:`backend.db.session.changed` (a topic: a table name)
  in the transaction; when its session ends, the :class:`~backend.db.session.Database`
  calls the runtime's hook, which drops what was read of those topics
  (:meth:`ReadCache.invalidate`);
- a read that started before an invalidation is not stored after it (a generation per
  topic), so a stale answer cannot outlive the write that made it stale;
- other processes on SQLite (another ``visioncell serve``, the CLI): the TTL bounds how
  long a change stays unseen here;
- roles are still checked per request: the cache sits inside the handlers, after the role
  dependency accepted the caller, and an entry read for a role is served to that role and
  stronger ones only.
"""

from __future__ import annotations

import time
from collections.abc import Awaitable, Callable, Hashable, Iterable
from dataclasses import dataclass
from typing import Any, TypeVar

from cachetools import TTLCache

from backend.cachebase import Flights, check_limits
from backend.db.models import Role
from backend.db.session import Changes

__all__ = ["Answer", "ReadCache"]

T = TypeVar("T")


@dataclass(frozen=True, eq=False)
class Answer:
    """One kept answer.  Equal only to itself: a new read makes a new one (the fast path
    of :mod:`backend.api.fastpath` keeps its rendered bytes per answer)."""

    #: The role it was read for (served to that role and stronger ones only).
    role: Role
    #: The topics it read.
    topics: frozenset[str]
    #: The answer, shared: not to be mutated.
    value: Any


class ReadCache:
    """Answers by key for ``ttl_s`` seconds, dropped when a topic they read is written.

    Parameters
    ----------
    ttl_s : float
        Reuse time, seconds, in [0, 10]; 0 turns the cache off.
    max_entries : int
        Most answers kept (the least recently used go first).
    clock : callable
        Monotonic seconds the TTL is counted in (a test gives its own).
    """

    def __init__(
        self, *, ttl_s: float = 1.0, max_entries: int = 512,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:  # fmt: skip
        check_limits(ttl_s, max_entries, 10.0)
        self._answers: TTLCache[Hashable, Answer] = TTLCache(max_entries, ttl_s, timer=clock)
        self._generation: dict[str, int] = {}
        self._epoch = 0  # grows with every clear()
        self._flights = Flights()
        #: Answers served from memory, and reads made (and :attr:`shared`).
        self.hits = 0
        self.misses = 0

    @property
    def ttl_s(self) -> float:
        """Reuse time, seconds (fixed when the cache is made)."""
        return float(self._answers.ttl)

    def _gen(self, topics: frozenset[str]) -> tuple[int, ...]:
        return (self._epoch, *(self._generation.get(t, 0) for t in sorted(topics)))

    async def get_or_read(
        self, key: Hashable, *, role: Role, topics: Iterable[str],
        read: Callable[[], Awaitable[T]],
    ) -> T:  # fmt: skip
        """The answer of ``key`` read for a role no stronger than ``role`` within the TTL
        and since the last change of ``topics``; else ``await read()``, kept.  Callers
        that miss while a read of ``key`` for a role no stronger than theirs is in flight
        share it.  The value is shared: not to be mutated."""
        if not isinstance(role, Role):
            raise TypeError(f"role must be a Role, got {role!r}")
        deps = frozenset(topics)
        if not deps or not all(isinstance(t, str) and t for t in deps):
            raise ValueError(f"topics must name at least one topic, got {topics!r}")
        if self.ttl_s <= 0:
            self.misses += 1
            return await read()
        found = self._answers.get(key)
        if found is not None and found.topics == deps and role >= found.role:
            self.hits += 1
            return found.value
        gen = self._gen(deps)

        async def read_and_keep() -> T:
            self.misses += 1
            value = await read()
            if self._gen(deps) == gen:  # nothing it read was written meanwhile
                self._answers[key] = Answer(role, deps, value)
            return value

        def may_share(tag: tuple[Role, tuple[int, ...]]) -> bool:
            return role >= tag[0] and tag[1] == gen

        return await self._flights.read(key, (role, gen), may_share, read_and_keep)

    def peek(self, key: Hashable, *, role: Role, topics: Iterable[str]) -> Answer | None:
        """The answer :meth:`get_or_read` would give ``key`` now for ``role`` without
        reading (the same TTL, topics and role rule; counted as a hit), or None."""
        found = self._answers.get(key)
        if (
            found is None or self.ttl_s <= 0 or role < found.role
            or found.topics != frozenset(topics)
        ):  # fmt: skip
            return None
        self.hits += 1
        return found

    @property
    def shared(self) -> int:
        """Callers that shared a read in flight instead of reading."""
        return self._flights.shared

    def invalidate(self, topics: Iterable[str]) -> int:
        """Drop the answers that read one of ``topics``; a read in progress is not kept
        after this.  Returns how many were dropped."""
        names = set(topics)
        for t in names:
            self._generation[t] = self._generation.get(t, 0) + 1
        gone = [k for k, a in list(self._answers.items()) if a.topics & names]
        for k in gone:
            self._answers.pop(k, None)
        return len(gone)

    def clear(self) -> None:
        """Drop every answer (a read in progress is not kept)."""
        self._epoch += 1
        self._flights.clear()
        self._answers.clear()

    def on_change(self, changes: Changes) -> None:
        """The database's hook: drop what was read of the changed topics."""
        self.invalidate(changes)

    def __len__(self) -> int:
        return len(self._answers)
