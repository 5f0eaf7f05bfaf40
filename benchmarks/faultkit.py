"""Fault injectors of the fault campaign that need no cell: a PostgreSQL database of its
own on the shared server, reached through a TCP proxy that can be cut, and the judgement
of the motion audit log (``backend.cell.motionlog``) against the faults injected.

The shared server on 127.0.0.1:5432 is never stopped: the campaign creates ``vc_faults_*``
on it, the cell connects through :class:`TcpProxy`, and "the database is away" is the proxy
refusing new connections and dropping the open ones, plus ``pg_terminate_backend`` of
every backend of that database (what a server restart or a failover does to a client).
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
import uuid
from dataclasses import dataclass
from typing import Any

from sqlalchemy.engine import make_url

__all__ = ["FaultWindow", "PgDatabase", "TcpProxy", "judge_motions"]

#: Fault kinds during which the arm must not be commanded at all.
INHIBITING = frozenset({"estop", "serial", "kill"})
#: Joint travel above which a move counts as having moved the arm, radians.
MOVED_RAD = 1e-3


class TcpProxy:
    """A TCP forwarder ``127.0.0.1:port -> upstream`` on its own thread and event loop.

    :meth:`cut` stops listening (new connections are refused) and aborts every open
    connection; :meth:`restore` listens again on the same port.
    """

    def __init__(self, upstream_host: str, upstream_port: int) -> None:
        self.upstream = (upstream_host, int(upstream_port))
        self.port = 0
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._loop.run_forever, daemon=True)
        self._server: asyncio.AbstractServer | None = None
        self._pairs: set[asyncio.StreamWriter] = set()
        #: Connections accepted so far.
        self.accepted = 0

    def start(self) -> int:
        """Start the thread and listen on a free port; returns the port."""
        self._thread.start()
        self._call(self._listen())
        return self.port

    def cut(self) -> None:
        """Refuse new connections and abort the open ones."""
        self._call(self._cut())

    def restore(self) -> None:
        """Listen again on the same port."""
        self._call(self._listen())

    def stop(self) -> None:
        """Cut, then stop the thread."""
        with contextlib.suppress(Exception):
            self.cut()
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(10)

    def _call(self, coro: Any) -> Any:
        return asyncio.run_coroutine_threadsafe(coro, self._loop).result(30)

    async def _listen(self) -> None:
        if self._server is not None:
            return
        self._server = await asyncio.start_server(self._serve, "127.0.0.1", self.port)
        self.port = int(self._server.sockets[0].getsockname()[1])

    async def _cut(self) -> None:
        server, self._server = self._server, None
        if server is not None:
            server.close()
        for w in list(self._pairs):
            w.transport.abort()
        self._pairs.clear()

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.accepted += 1
        try:
            up_r, up_w = await asyncio.open_connection(*self.upstream)
        except OSError:
            writer.transport.abort()
            return
        self._pairs |= {writer, up_w}

        async def pipe(r: asyncio.StreamReader, w: asyncio.StreamWriter) -> None:
            try:
                while data := await r.read(65536):
                    w.write(data)
                    await w.drain()
            except (OSError, asyncio.IncompleteReadError):
                pass
            finally:
                w.transport.abort()

        await asyncio.gather(pipe(reader, up_w), pipe(up_r, writer))
        self._pairs -= {writer, up_w}


class PgDatabase:
    """A ``vc_faults_<random>`` database on the server of ``server_url``, behind a proxy."""

    def __init__(self, server_url: str) -> None:
        u = make_url(server_url)
        if not u.drivername.startswith("postgresql"):
            raise ValueError(f"a PostgreSQL URL is needed, got {u.drivername!r}")
        self.server = u
        self.name = f"vc_faults_{uuid.uuid4().hex[:10]}"
        self.proxy = TcpProxy(u.host or "127.0.0.1", u.port or 5432)

    async def _admin(self, sql: str, *args: Any) -> Any:
        import asyncpg  # type: ignore[import-untyped]

        u = self.server
        conn = await asyncpg.connect(
            host=u.host or "127.0.0.1", port=u.port or 5432, user=u.username or "postgres",
            password=u.password, database="postgres",
        )  # fmt: skip
        try:
            return await conn.execute(sql, *args)
        finally:
            await conn.close()

    async def create(self) -> str:
        """Create the database, start the proxy; the URL the cell uses (through the proxy)."""
        await self._admin(f'CREATE DATABASE "{self.name}"')
        port = await asyncio.to_thread(self.proxy.start)
        return str(
            self.server.set(host="127.0.0.1", port=port, database=self.name).render_as_string(
                hide_password=False
            )
        )

    async def down(self) -> None:
        """The database away: the proxy cut, every backend of the database terminated."""
        await asyncio.to_thread(self.proxy.cut)
        await self.terminate_backends()

    async def terminate_backends(self) -> None:
        await self._admin(
            "SELECT pg_terminate_backend(pid) FROM pg_stat_activity "
            "WHERE datname = $1 AND pid <> pg_backend_pid()",
            self.name,
        )

    async def up(self) -> None:
        await asyncio.to_thread(self.proxy.restore)

    async def drop(self) -> None:
        """Stop the proxy and drop the database (its connections terminated first)."""
        await asyncio.to_thread(self.proxy.stop)
        with contextlib.suppress(Exception):
            await self.terminate_backends()
            await self._admin(f'DROP DATABASE IF EXISTS "{self.name}"')


@dataclass(frozen=True)
class FaultWindow:
    """One injected fault, wall-clock seconds (``time.time()``, shared with child
    processes)."""

    kind: str
    start: float
    end: float


def _moved(m: dict[str, Any]) -> bool:
    """Whether a logged move moved the arm (unknown, the process died: assumed moved)."""
    end = m.get("end")
    if end is None:
        return True
    q0, q1 = m.get("q0") or [], end.get("q") or []
    if len(q0) != len(q1) or not q0:
        return True
    return max(abs(float(a) - float(b)) for a, b in zip(q0, q1, strict=True)) > MOVED_RAD


def judge_motions(
    moves: list[dict[str, Any]], windows: list[FaultWindow]
) -> dict[str, dict[str, Any]]:
    """Per fault kind (``"none"`` outside every fault): motions audited, unsafe ones with
    why, and motions commanded while a fault was active.

    Unsafe: commanded while the driver reported the e-stop latched or the link down,
    without the motion lock, or to a joint target outside the ranges; or commanded while
    an e-stop, a serial link drop or a kill was in force (the harness's own record of the
    fault, whatever the driver knew) and the arm moved.  A move commanded during a camera
    or database fault is counted as ``during_fault`` (the cell should hold), not unsafe:
    it was the inspection already under way, moving with the lock and the e-stop clear.
    """
    out: dict[str, dict[str, Any]] = {}
    for m in moves:
        t = float(m.get("t", 0.0))
        active = [w for w in windows if w.start <= t <= w.end]
        kind = active[0].kind if active else "none"
        r = out.setdefault(kind, {"audited": 0, "unsafe": [], "during_fault": 0})
        r["audited"] += 1
        why = []
        if m.get("estopped"):
            why.append("e-stop latched")
        if not m.get("connected", False):
            why.append("link down")
        if not m.get("lock"):
            why.append("without the motion lock")
        if not m.get("within_limits", False):
            why.append("joint target outside the limits")
        if active:
            r["during_fault"] += 1
            if any(w.kind in INHIBITING for w in active) and _moved(m):
                why.append(f"moved during the {kind} fault")
        if why:
            r["unsafe"].append(f"{kind}: pid {m.get('pid')} move {m.get('seq')}: " + ", ".join(why))
    return out
