"""A database outage inside the process, for the E-STOP's benchmark and tests.

:class:`DatabaseOutage` replaces :meth:`backend.db.session.Database.session` of one
database while it lasts: in ``fail`` mode every new session raises SQLAlchemy's
``OperationalError`` at once (the file unreadable, the server refusing connections); in
``block`` mode every new session waits until the outage ends (a SQLite file locked by
another process, a PostgreSQL server that accepts but never answers), then goes on with a
real session.  Sessions opened before the outage are not touched.  Any thread may start
and end it (the app runs on uvicorn's thread, the benchmark on its own).
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
from collections.abc import AsyncIterator, Iterator
from typing import Any

from sqlalchemy.exc import OperationalError

__all__ = ["DatabaseOutage"]

#: How often a blocked session looks whether the outage ended, seconds.
_POLL_S = 0.02


class DatabaseOutage:
    """The database ``db`` unavailable between :meth:`start` and :meth:`end`.

    Parameters
    ----------
    db : backend.db.session.Database
        The database to take away.
    mode : str
        ``"fail"``: sessions raise at once; ``"block"``: sessions wait for the end.
    """

    def __init__(self, db: Any, *, mode: str = "block") -> None:
        if mode not in ("fail", "block"):
            raise ValueError(f"mode must be 'fail' or 'block', got {mode!r}")
        self.db = db
        self.mode = mode
        self._over = threading.Event()
        self._real: Any = None
        self._active = False
        #: Sessions refused or held back so far.
        self.hit = 0

    @contextlib.asynccontextmanager
    async def _session(self) -> AsyncIterator[Any]:
        self.hit += 1
        if self.mode == "fail":
            raise OperationalError("BEGIN", {}, Exception("database unavailable (injected)"))
        while not self._over.is_set():
            await asyncio.sleep(_POLL_S)
        assert self._real is not None
        async with self._real() as session:
            yield session

    def start(self) -> None:
        """Begin the outage (new sessions fail or wait)."""
        if self._active:
            raise RuntimeError("the outage has started already")
        self._active = True
        self._over.clear()
        self._real = self.db.session
        self.db.session = self._session

    def end(self) -> None:
        """End the outage: sessions work again, the blocked ones go on."""
        if not self._active:
            return
        self._active = False
        del self.db.session  # the instance attribute: the class's method shows again
        self._over.set()

    def __enter__(self) -> DatabaseOutage:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.end()

    @contextlib.contextmanager
    def paused(self) -> Iterator[None]:
        """End the outage for the body of a ``with`` and start it again after."""
        self.end()
        try:
            yield
        finally:
            self.start()
