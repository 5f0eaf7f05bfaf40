"""Give a running cell caches counted on the test's clock."""

from __future__ import annotations

from typing import Any

from backend.caches import AuthCache, ReadCache
from tests.utils.clock import SteppedClock

__all__ = ["clocked_caches"]


def clocked_caches(
    rt: Any, clock: SteppedClock, *, read_ttl_s: float = 1.0, auth_ttl_s: float = 2.0
) -> None:
    """Replace the read and sign-in caches of the running ``rt`` with ones counted on
    ``clock`` (hooked to its database like the runtime's own)."""
    db = rt.database
    db.on_change.remove(rt.read_cache.on_change)
    db.on_change.remove(rt.auth_cache.on_change)
    rt.read_cache = ReadCache(ttl_s=read_ttl_s, clock=clock)
    rt.auth_cache = AuthCache(ttl_s=auth_ttl_s, clock=clock, known=rt.known_tokens)
    db.on_change += [rt.read_cache.on_change, rt.auth_cache.on_change]
