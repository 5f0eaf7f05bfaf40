"""Tokens this process has seen valid recently, for the emergency stop.

E-STOP must answer whatever the database is doing, so its sign-in never reads the
database: it accepts a token that the sign-in cache holds (:mod:`backend.caches`) or
one kept here.  :class:`KnownTokens` remembers, by the token's HMAC (never the token),
every token a sign-in of this process found valid (REST, the console's WebSocket, the 3D
view's panel, the live tokens read once at start-up) with its user and role, for
:data:`TTL_S` seconds from the last time it was seen.

What keeps it safe:

- only the emergency stop reads it: at worst a token revoked elsewhere may still stop the
  cell for the rest of its hour, never move it;
- a change of this process to a user or a token (revocation, role change, disabling,
  deletion) drops that user's entries when its session ends
  (:func:`backend.caches.users_changed`), and on PostgreSQL so does another process's
  (its notification);
- memory is bounded: at most ``max_entries`` tokens, the least recently seen go first.
"""

from __future__ import annotations

import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass

__all__ = ["MAX_ENTRIES", "TTL_S", "KnownToken", "KnownTokens"]

#: How long a token seen valid is accepted by the emergency stop, seconds (one hour).
TTL_S = 3600.0
#: Most tokens remembered.
MAX_ENTRIES = 10_000


@dataclass(frozen=True)
class KnownToken:
    """A token seen valid: whose it is and when."""

    user_id: int
    """Id of the token's user."""
    user: str
    """Name of the token's user."""
    role: str
    """The user's role name when the token was seen (``viewer``, ``operator``, ``engineer``)."""
    seen_s: float
    """When the token was last seen valid, the clock's seconds."""


class KnownTokens:
    """Token hashes seen valid in the last ``ttl_s`` seconds (thread-safe: the 3D view's
    sign-ins run on viser's threads).

    Parameters
    ----------
    ttl_s : float
        How long an entry is accepted after the token was last seen valid, seconds, in
        (0, 86400].
    max_entries : int
        Most tokens kept, 1..1e6 (the least recently seen is dropped first).
    clock : callable, optional
        Monotonic seconds (tests pass their own).
    """

    def __init__(
        self,
        *,
        ttl_s: float = TTL_S,
        max_entries: int = MAX_ENTRIES,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if isinstance(ttl_s, bool) or not 0.0 < float(ttl_s) <= 86_400.0:
            raise ValueError(f"ttl_s must be within (0, 86400] s, got {ttl_s!r}")
        if isinstance(max_entries, bool) or not 1 <= int(max_entries) <= 1_000_000:
            raise ValueError(f"max_entries must be within 1..1e6, got {max_entries!r}")
        self.ttl_s = float(ttl_s)
        self.max_entries = int(max_entries)
        self._clock = clock
        self._entries: OrderedDict[str, KnownToken] = OrderedDict()
        self._lock = threading.Lock()

    def note(self, token_hash: str, *, user_id: int, user: str, role: str) -> None:
        """Remember that ``token_hash`` signed ``user`` (``role``) in just now."""
        if not isinstance(token_hash, str) or not 1 <= len(token_hash) <= 128:
            raise ValueError(f"token_hash must be a short hex digest, got {token_hash!r:.80}")
        entry = KnownToken(int(user_id), str(user)[:64], str(role)[:16], self._clock())
        with self._lock:
            self._entries.pop(token_hash, None)
            self._entries[token_hash] = entry  # most recently seen last
            while len(self._entries) > self.max_entries:
                self._entries.popitem(last=False)

    def get(self, token_hash: str) -> KnownToken | None:
        """The entry of ``token_hash`` if it was seen valid within :attr:`ttl_s` (an older
        one is dropped), else None."""
        now = self._clock()
        with self._lock:
            entry = self._entries.get(token_hash)
            if entry is None:
                return None
            if now - entry.seen_s > self.ttl_s:
                del self._entries[token_hash]
                return None
            return entry

    def forget_users(self, user_ids: frozenset[int] | set[int] | None) -> int:
        """Drop the entries of ``user_ids`` (None: every entry); returns how many."""
        with self._lock:
            if user_ids is None:
                n = len(self._entries)
                self._entries.clear()
                return n
            gone = [k for k, e in self._entries.items() if e.user_id in user_ids]
            for k in gone:
                del self._entries[k]
            return len(gone)

    def __len__(self) -> int:
        with self._lock:
            return len(self._entries)
