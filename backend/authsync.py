"""Drop the sign-ins another process of the plant revoked, as soon as it commits.

Each process keeps successful sign-ins for a few seconds
(:class:`~backend.caches.AuthCache`).  On PostgreSQL every transaction that revokes,
changes or deletes a token or a user notifies :data:`~backend.caches.AUTH_CHANNEL` with the
user ids (:func:`backend.caches.users_changed`); :class:`AuthSync` LISTENs on it over its
own asyncpg connection and drops those users' entries from this process's cache on each
notification.

While the listening connection is down (the database away, a network cut) the cache's TTL
is the fallback, as on SQLite; the task reconnects with :class:`robot.backoff.Backoff` and,
once listening again, forgets every entry (notifications sent meanwhile were missed).
A keep-alive query every :data:`KEEPALIVE_S` finds a connection that died silently.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from dataclasses import dataclass
from typing import Any

from sqlalchemy.engine import make_url

from backend.caches import AUTH_CHANNEL, AuthCache, parse_payload
from backend.taskutil import cancel_and_wait
from robot.backoff import Backoff

__all__ = ["KEEPALIVE_S", "AuthSync", "AuthSyncStats"]

log = logging.getLogger(__name__)

#: Period of the keep-alive query on the listening connection, s.
KEEPALIVE_S = 15.0
#: Timeout of connecting and of one keep-alive query, s.
STEP_TIMEOUT_S = 10.0


@dataclass
class AuthSyncStats:
    """Counters of the listening task (for the status page and tests)."""

    listening: bool = False
    """Whether the LISTEN connection is open now."""
    notifications: int = 0
    """Notifications received."""
    dropped: int = 0
    """Cache entries dropped because of them."""
    connects: int = 0
    """Successful (re)connections."""
    last_error: str = ""
    """The last connection error, empty if none."""


class AuthSync:
    """The task that applies the plant's sign-in changes to ``cache`` (see the module doc).

    Parameters
    ----------
    url : str
        The PostgreSQL URL of the plant's database (``postgresql+asyncpg://...``).
    cache : AuthCache
        This process's sign-in cache.
    """

    def __init__(self, url: str, cache: AuthCache) -> None:
        if not url.startswith("postgresql"):
            raise ValueError(f"AuthSync needs a PostgreSQL URL, got {url.split(':', 1)[0]!r}")
        self.url = url
        self.cache = cache
        self.stats = AuthSyncStats()
        self._conn: Any = None
        self._lost = asyncio.Event()
        self._task: asyncio.Task[None] | None = None
        #: Set each time the LISTEN is in place (tests wait on it).
        self.ready = asyncio.Event()

    def start(self) -> None:
        """Start the task (inside the running loop)."""
        if self._task is None:
            self._task = asyncio.get_running_loop().create_task(self._run(), name="auth-sync")

    async def stop(self) -> None:
        """Stop the task and close the connection."""
        task, self._task = self._task, None
        if task is not None:
            await cancel_and_wait(task)  # not a bare cancel: wait_for may swallow one
        await self._close()

    async def _run(self) -> None:
        backoff = Backoff(initial_s=0.5, max_s=30.0)
        while True:
            try:
                await asyncio.wait_for(self._listen(), STEP_TIMEOUT_S)
            except asyncio.CancelledError:
                raise
            except Exception as exc:
                if not self.stats.last_error:  # once per outage
                    log.warning("sign-in sync: cannot LISTEN (%s); the cache's TTL applies", exc)
                self.stats.last_error = f"{type(exc).__name__}: {exc}"[:300]
                await self._close()
                await backoff.sleep()
                continue
            backoff.reset()
            if self.stats.last_error:
                log.info("sign-in sync: listening again")
            self.stats.last_error = ""
            # Changes committed while we were not listening were not heard: forget them all.
            self.cache.forget_users(None)
            self.ready.set()
            while not self._lost.is_set():
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(self._lost.wait(), KEEPALIVE_S)
                if self._lost.is_set():
                    break
                try:
                    await asyncio.wait_for(self._conn.execute("SELECT 1"), STEP_TIMEOUT_S)
                except asyncio.CancelledError:
                    raise
                except Exception as exc:
                    self.stats.last_error = f"keep-alive: {type(exc).__name__}: {exc}"[:300]
                    log.warning("sign-in sync: the listening connection is lost (%s)", exc)
                    break
            self.ready.clear()
            await self._close()

    async def _listen(self) -> None:
        import asyncpg  # type: ignore[import-untyped]

        u = make_url(self.url)
        conn = await asyncpg.connect(
            host=u.host or "127.0.0.1",
            port=u.port or 5432,
            user=u.username,
            password=u.password,
            database=u.database,
        )
        try:
            self._lost.clear()
            conn.add_termination_listener(lambda _c: self._lost.set())
            await conn.add_listener(AUTH_CHANNEL, self._on_notify)
        except BaseException:
            conn.terminate()
            raise
        self._conn = conn
        self.stats.listening = True
        self.stats.connects += 1

    def _on_notify(self, _conn: Any, _pid: int, _channel: str, payload: str) -> None:
        self.stats.notifications += 1
        self.stats.dropped += self.cache.forget_users(parse_payload(payload))

    async def _close(self) -> None:
        conn, self._conn = self._conn, None
        self.stats.listening = False
        if conn is not None:
            with contextlib.suppress(Exception):
                await asyncio.wait_for(conn.close(), 2.0)
            if not conn.is_closed():
                conn.terminate()
