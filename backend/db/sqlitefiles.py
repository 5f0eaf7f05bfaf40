"""Guard the SQLite write-ahead log's side files against changes made outside VisionCell.

In WAL mode every connection maps the ``-shm`` file (the WAL index) into memory; SQLite
always maps it, whatever ``PRAGMA mmap_size`` says (that pragma covers the main database
file only, and is 0 by default).  When something outside the process shrinks that file
(truncates it, or writes it anew with ``>``) while the connections hold it mapped, the next
read of the mapping by the driver's worker thread is a ``SIGBUS``: the process dies at
once, with no Python exception to catch and no log line.

:class:`GuardedPool` checks the side files before handing out a connection (every session,
``engine.connect()`` and the pool's pre-ping go through it):

* a ``-shm`` shorter than the mapped size it had is grown back to that size; the bytes
  grown are zeros, which SQLite reads as an index to rebuild, and it rebuilds it from the
  ``-wal`` under its own lock (its normal recovery path); the log says so once;
* a ``-shm`` or ``-wal`` that is not a regular file or not writable by this process makes
  the checkout fail with the driver's ``OperationalError``, which the API answers
  ``503 database_unavailable`` (and the cell's store retries wait out), with one log line
  per outage, until the file is writable again.

A shrink that lands between the check and the driver's next read can still fault;
``visioncell serve`` enables :mod:`faulthandler`, so that fatal signal ends the process
with a clear line and every thread's stack on stderr, and the next start-up recovers
(the interrupted jobs and inspections are marked by the start-up).
"""

from __future__ import annotations

import logging
import os
import stat
import threading
from pathlib import Path
from typing import Any

from sqlalchemy.pool import AsyncAdaptedQueuePool

__all__ = ["REGION_BYTES", "GuardedPool", "SideFileProblem", "check_side_files", "guarded_pool_for"]

log = logging.getLogger(__name__)
#: SQLAlchemy logs a pool's life ("Pool disposed", "Pool recreating") at INFO on a logger
#: named after the pool's class, and keeps its own ``sqlalchemy`` loggers at WARNING; a
#: pool class defined here logs under this module instead, so without this its lines land
#: among ``visioncell serve``'s start-up banner.
logging.getLogger(f"{__name__}.GuardedPool").setLevel(logging.WARNING)

#: SQLite's WAL index grows in regions of 32 KiB.
REGION_BYTES = 32 * 1024
#: Frames indexed by one region (the first region holds fewer, 4062: take the smaller).
_FRAMES_PER_REGION = 4062
_WAL_HEADER = 32
_FRAME_HEADER = 24


class SideFileProblem(Exception):
    """A side file of the database cannot be used (the message says which and why)."""


class _State:
    """What the guard knows of one database file."""

    def __init__(self, path: str) -> None:
        self.path = path
        self.shm_seen = 0
        self.lock = threading.Lock()
        self.refusing = False


def _needed_shm_bytes(wal: str, shm_seen: int) -> int:
    """The -shm size that covers every region the WAL can have needed (a lower bound)."""
    try:
        wal_bytes = os.stat(wal).st_size
    except OSError:
        return shm_seen
    page = 4096
    try:
        with open(wal, "rb") as f:
            header = f.read(_WAL_HEADER)
        if len(header) == _WAL_HEADER:
            page = int.from_bytes(header[8:12], "big") or 65536
    except OSError:
        pass
    frames = max(0, wal_bytes - _WAL_HEADER) // (page + _FRAME_HEADER)
    regions = frames // _FRAMES_PER_REGION + 1
    return max(shm_seen, regions * REGION_BYTES)


def check_side_files(state: _State) -> None:
    """Heal a shrunk ``-shm`` (see the module's notes) and raise :class:`SideFileProblem`
    for a side file that is not a writable regular file."""
    shm, wal = state.path + "-shm", state.path + "-wal"
    for side in (shm, wal):
        try:
            st = os.stat(side)
        except FileNotFoundError:
            continue  # SQLite makes them when it needs them
        except OSError as exc:
            raise SideFileProblem(f"cannot stat {side}: {exc}") from None
        if not stat.S_ISREG(st.st_mode):
            raise SideFileProblem(f"{side} is not a regular file")
        if not os.access(side, os.R_OK | os.W_OK):
            raise SideFileProblem(f"{side} is not writable by this process")
        if side == shm and st.st_size < state.shm_seen:
            size = _needed_shm_bytes(wal, state.shm_seen)
            try:
                with open(shm, "r+b") as f:
                    f.truncate(size)  # zeros: SQLite rebuilds the index from the WAL
            except OSError as exc:
                raise SideFileProblem(f"cannot restore {shm}: {exc}") from None
            log.error(
                "the SQLite index file %s was shrunk outside VisionCell (%d bytes, %d mapped):"
                " grown back to %d bytes with zeros, SQLite rebuilds it from the WAL",
                shm, st.st_size, state.shm_seen, size,
            )  # fmt: skip
            state.shm_seen = size


def guarded_pool_for(sqlite_path: str) -> type[GuardedPool]:
    """A :class:`GuardedPool` class for the database file ``sqlite_path``."""
    return type("GuardedPool", (GuardedPool,), {"sqlite_path": str(Path(sqlite_path))})


def _note_size(state: _State) -> None:
    try:
        size = os.stat(state.path + "-shm").st_size
    except OSError:
        return
    state.shm_seen = max(state.shm_seen, size)


class GuardedPool(AsyncAdaptedQueuePool):
    """SQLAlchemy's async queue pool with :func:`check_side_files` before every checkout;
    made per database file by :func:`guarded_pool_for` (the pool recreates itself from its
    class, so the path is a class attribute)."""

    sqlite_path: str = ""

    def __init__(self, *args: Any, **kw: Any) -> None:
        super().__init__(*args, **kw)
        self._vc_state = _State(self.sqlite_path)

    def connect(self) -> Any:  # type: ignore[override, unused-ignore]
        state = self._vc_state
        dialect: Any = self._dialect  # an async adapter dialect: its DB-API is loaded_dbapi
        with state.lock:
            try:
                check_side_files(state)
            except SideFileProblem as exc:
                if not state.refusing:
                    log.error("database unavailable: %s; answering 503 until it is fixed", exc)
                    state.refusing = True
                raise dialect.loaded_dbapi.OperationalError(
                    f"the database's side file cannot be used: {exc}"
                ) from None
            if state.refusing:
                log.warning("database side files usable again: %s", state.path)
                state.refusing = False
        conn = super().connect()
        _note_size(state)
        return conn

    def _do_return_conn(self, record: Any) -> None:
        _note_size(self._vc_state)
        super()._do_return_conn(record)
