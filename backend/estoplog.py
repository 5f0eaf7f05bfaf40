"""The audit record of every emergency stop, written after the stop itself.

The stop must never wait for the database (:meth:`backend.cell.Cell.estop`), so its
record is not written in the request: :class:`EStopLog` listens to the cell's
:class:`~backend.cell.events.CellStopped` events, queues each press and reset (at most
:data:`MAX_PENDING`) and writes them to the audit trail (kind ``estop``, the cell's name as
the entity) in a task of its own.  While the database is unavailable the writer retries
with backoff, so a record made during an outage is written once the database is back.  A
record that cannot be written (the outage outlasts :data:`MAX_WAIT_S`, the queue
overflows, or the process stops first) is logged at error level with its whole content.
"""

from __future__ import annotations

import asyncio
import functools
import logging
from collections import deque
from dataclasses import dataclass
from datetime import datetime
from typing import Any

from backend import audit
from backend.cell.events import CellStopped, EventBus
from backend.db.session import Database
from backend.db.types import utcnow
from backend.inspection.recovery import is_database_error, retry_database
from backend.taskutil import cancel_and_wait

__all__ = ["MAX_PENDING", "MAX_WAIT_S", "EStopLog", "EStopRecord"]

log = logging.getLogger(__name__)

#: Most records waiting for the database (beyond it the oldest is logged and dropped).
MAX_PENDING = 256
#: Longest a record waits for the database, seconds (then it is logged and dropped).
MAX_WAIT_S = 24 * 3600.0


@dataclass(frozen=True)
class EStopRecord:
    """One press (``active``) or reset of the emergency stop, as the audit stores it."""

    at: datetime
    """When the event was made (UTC)."""
    event: CellStopped
    """The cell's event."""

    def new_value(self) -> dict[str, Any]:
        """The audit row's ``new`` value."""
        e = self.event
        return {
            "active": e.active,
            "source": e.source,
            "conveyors": list(e.conveyors),
            "arm_latched": e.arm_latched,
            "jobs": list(e.jobs),
            "at": self.at.isoformat(),
        }

    def describe(self) -> str:
        """One line for the log."""
        e = self.event
        what = "E-STOP" if e.active else "E-STOP reset"
        return f"{what} by {e.by} ({e.role}) via {e.source} at {self.at.isoformat()}: {self.new_value()}"


class EStopLog:
    """Writes the emergency stops of one cell to the audit trail (see the module doc).

    Parameters
    ----------
    db : Database
        Where the audit trail lives.
    cell_name : str
        The audit rows' entity id.
    max_wait_s : float
        Longest a record waits for the database, seconds, in (0, 7 days].
    """

    def __init__(self, db: Database, cell_name: str, *, max_wait_s: float = MAX_WAIT_S) -> None:
        if not 0.0 < float(max_wait_s) <= 7 * 86400.0:
            raise ValueError(f"max_wait_s must be within (0, 604800] s, got {max_wait_s!r}")
        self.db = db
        self.cell_name = cell_name
        self.max_wait_s = float(max_wait_s)
        self._pending: deque[EStopRecord] = deque()
        self._wake = asyncio.Event()
        self._task: asyncio.Task[None] | None = None
        self._remove: Any = None
        #: Records written to the audit trail.
        self.written = 0
        #: Records given up (logged at error level instead).
        self.lost = 0

    def start(self, bus: EventBus) -> None:
        """Listen to ``bus`` and start the writer."""
        if self._task is not None:
            raise RuntimeError("the E-STOP log is running already")
        self._remove = bus.add_listener(self._on_event, CellStopped)
        self._task = asyncio.get_running_loop().create_task(self._run(), name="estop-audit")

    async def stop(self) -> None:
        """Stop listening and writing; records not written yet are logged at error level."""
        if self._remove is not None:
            self._remove()
            self._remove = None
        if self._task is not None:
            await cancel_and_wait(self._task)
            self._task = None
        while self._pending:
            self._give_up(self._pending.popleft(), "the cell stopped before it was written")

    @property
    def pending(self) -> int:
        """Records waiting to be written."""
        return len(self._pending)

    def _on_event(self, event: CellStopped) -> None:
        """The bus's listener: queue the record (on the event loop, never blocks)."""
        if len(self._pending) >= MAX_PENDING:
            self._give_up(self._pending.popleft(), f"more than {MAX_PENDING} records waited")
        self._pending.append(EStopRecord(utcnow(), event))
        self._wake.set()

    def _give_up(self, record: EStopRecord, why: str) -> None:
        self.lost += 1
        log.error("audit record NOT written (%s): %s", why, record.describe())

    async def _write(self, record: EStopRecord) -> None:
        e = record.event
        actor = audit.Actor(e.by or "system", e.role or "system")
        async with self.db.session() as session:
            audit.record(
                session, actor=actor, kind="estop", entity_id=self.cell_name,
                action="press" if e.active else "reset", old=None, new=record.new_value(),
                reason=None,
            )  # fmt: skip

    async def _run(self) -> None:
        while True:
            await self._wake.wait()
            self._wake.clear()
            while self._pending:
                record = self._pending[0]
                try:
                    await retry_database(
                        "recording an emergency stop", functools.partial(self._write, record),
                        max_wait_s=self.max_wait_s,
                    )  # fmt: skip
                except asyncio.CancelledError:
                    raise
                except Exception as exc:
                    why = "database unavailable" if is_database_error(exc) else repr(exc)
                    if self._pending and self._pending[0] is record:
                        self._pending.popleft()
                    self._give_up(record, why)
                    continue
                if self._pending and self._pending[0] is record:
                    self._pending.popleft()
                self.written += 1
