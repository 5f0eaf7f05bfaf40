"""Sign-in of a PLC or an MES over OPC UA: a VisionCell user's name and one of its API tokens.

VisionCell users have no passwords: a program signs in with a token issued to it
(``visioncell user add plc --role operator`` prints one).  OPC UA's user-name identity
token carries the user's name and, as the password, that token; the pair is accepted when
the token is live (neither revoked nor expired), its user is enabled and has that name.
The session then acts with the user's role (viewer reads; operator triggers, runs and
resets; engineer also selects recipes).

OPC UA servers check a sign-in synchronously (asyncua's ``UserManager.get_user``), so the
check reads a table of the live tokens' HMACs held in memory; :meth:`Credentials.refresh`
re-reads it from the database (asynchronously, when a client opens a session, before it
signs in), so a token issued or revoked a moment ago is honoured on the next connection.
"""

from __future__ import annotations

import hmac
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from sqlalchemy import select

from backend.auth import hash_token, live_token_clause, well_formed
from backend.db.models import ApiToken, Role, User

__all__ = ["MAX_CREDENTIALS", "Credential", "Credentials"]

#: Most live tokens held for sign-ins.
MAX_CREDENTIALS = 100_000


@dataclass(frozen=True)
class Credential:
    """A live token's user."""

    name: str
    role: Role


class Credentials:
    """The live tokens' HMACs and their users (thread-safe: checked on the OPC UA thread).

    Parameters
    ----------
    database : Database
        Where users and tokens are stored.
    secret : str
        The tokens' HMAC key (``Settings.secret_key``).
    min_refresh_s : float
        Shortest interval between two reads of the table (many connections at once read it
        once).
    clock : callable, optional
        Monotonic seconds.
    """

    def __init__(self, database: Any, secret: str, *, min_refresh_s: float = 0.5,
                 clock: Callable[[], float] = time.monotonic) -> None:  # fmt: skip
        self._db = database
        self._secret = secret
        self._by_hash: dict[str, Credential] = {}
        self._lock = threading.Lock()
        self._min_refresh_s = float(min_refresh_s)
        self._clock = clock
        self._last: float | None = None
        self.failures = 0

    async def refresh(self, *, force: bool = False) -> int:
        """Re-read the live tokens of enabled users; returns how many are held."""
        now = self._clock()
        if not force and self._last is not None and now - self._last < self._min_refresh_s:
            return len(self._by_hash)
        async with self._db.session() as session:
            rows = await session.execute(
                select(ApiToken.token_hash, User.name, User.role)
                .join(User, ApiToken.user_id == User.id)
                .where(live_token_clause(), User.disabled.is_(False))
                .limit(MAX_CREDENTIALS)
            )
            table = {str(h): Credential(str(n), Role[str(r)]) for h, n, r in rows.all()}
        with self._lock:
            self._by_hash = table
            self._last = now
        return len(table)

    def check(self, name: object, password: object) -> Credential | None:
        """The credential when ``password`` is a live token of the user called ``name``."""
        if not isinstance(name, str) or not isinstance(password, str | bytes):
            return None
        token = password.decode("utf-8", "replace") if isinstance(password, bytes) else password
        if not well_formed(token) or len(name) > 64:
            self.failures += 1
            return None
        with self._lock:
            cred = self._by_hash.get(hash_token(token, self._secret))
        if cred is None or not hmac.compare_digest(cred.name.encode(), name.encode()):
            self.failures += 1
            return None
        return cred
