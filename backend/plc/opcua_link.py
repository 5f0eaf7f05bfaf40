"""The OPC UA link: the server (:mod:`backend.plc.opcua`) in a child process of its own,
bridged to the cell's :class:`~backend.plc.handshake.Handshake` over a pipe.

Why a process: asyncua builds its address space and parses the OPC 40100 nodesets in long
CPU-bound stretches (seconds); on a thread of the cell's process they hold the interpreter
lock, and the cell's event loop (the E-STOP's) waited up to seconds behind them.  In a
child process nothing of that touches the cell.

Messages (pickled tuples) on one duplex pipe:

- cell -> server: ``("snap", Snapshot)`` after every change of the handshake,
  ``("reply", id, value)`` to a request, ``("stop",)``;
- server -> cell: ``("ready", load_s)`` once listening, ``("failed", text)``,
  ``("req", id, "cmd", name, (user, role), args)`` a method call of a signed-in user,
  ``("req", id, "refresh")`` the sign-in tables (before each new session signs in).

The cell's side sends from a thread of its own (a large sign-in table never blocks the
loop on a full pipe) and reads with the loop's reader callback.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
import multiprocessing
import queue
import threading
from pathlib import Path
from typing import Any

from backend.db.models import Role
from backend.plc.handshake import ErrorCode, Handshake, LinkUser, Snapshot
from backend.plc.signin import Credentials

__all__ = ["OpcUaLink"]

log = logging.getLogger(__name__)

#: Longest wait for the child to listen or to end, seconds (a hang's bound).
BOUND_S = 300.0


class OpcUaLink:
    """The OPC UA server for ``handshake`` in a child process (see the module docstring).

    Parameters
    ----------
    handshake : Handshake
    credentials : Credentials
        The sign-in tables, read from the database in this process.
    endpoint, anonymous_read, nodesets, security, cert_dir
        As :class:`backend.plc.opcua.OpcUaServer`.
    throttle : dict, optional
        ``SignInThrottle`` parameters for the server's failed sign-ins per address.
    """

    def __init__(self, handshake: Handshake, credentials: Credentials, *, endpoint: str,
                 anonymous_read: bool = False, nodesets: list[Path] | None = None,
                 throttle: dict[str, Any] | None = None, security: str = "none",
                 cert_dir: Path | None = None, secret: str = "") -> None:  # fmt: skip
        self.handshake = handshake
        self.credentials = credentials
        self.endpoint = endpoint
        self.config = {
            "endpoint": endpoint, "anonymous_read": anonymous_read,
            "nodesets": [str(p) for p in nodesets or []], "throttle": throttle,
            "security": security, "cert_dir": None if cert_dir is None else str(cert_dir),
            "secret": secret, "user_certificates": credentials.user_certificates is not None,
            "log_level": logging.getLogger().getEffectiveLevel(),
        }  # fmt: skip
        self.load_s: float | None = None
        """Seconds the nodesets took to load (once ready)."""
        self.error: str | None = None
        """Why the server did not start or stopped (None: it runs, or is starting)."""
        self._proc: Any = None
        self._conn: Any = None
        self._out: queue.SimpleQueue[Any] = queue.SimpleQueue()
        self._sender: threading.Thread | None = None
        self._ready: asyncio.Future[None] | None = None
        self._tasks: set[asyncio.Task[Any]] = set()
        self._loop: asyncio.AbstractEventLoop | None = None

    async def start(self) -> None:
        """Start the child and return at once; :meth:`wait_ready` waits until it listens."""
        self._loop = asyncio.get_running_loop()
        self._ready = self._loop.create_future()
        ctx = multiprocessing.get_context("spawn")  # never fork a process with threads
        mine, theirs = ctx.Pipe(duplex=True)
        self._conn = mine
        self._proc = ctx.Process(target=child_main, args=(theirs, self.config),
                                 name="visioncell-opcua", daemon=True)  # fmt: skip
        await asyncio.to_thread(self._proc.start)
        theirs.close()
        self._sender = threading.Thread(target=self._send_loop, name="opcua-pipe", daemon=True)
        self._sender.start()
        self._loop.add_reader(mine.fileno(), self._on_readable)
        self.handshake.add_listener(self._on_snapshot)

    async def wait_ready(self, timeout_s: float = BOUND_S) -> None:
        """Wait until the server listens (its start-up error, or ``TimeoutError``)."""
        assert self._ready is not None, "start() first"
        await asyncio.wait_for(asyncio.shield(self._ready), timeout_s)

    @property
    def ready(self) -> bool:
        """Whether the server listens now."""
        return self._ready is not None and self._ready.done() and self._ready.exception() is None

    async def stop(self) -> None:
        """Ask the child to stop, wait for it (off the loop), kill it if it hangs."""
        if self._loop is not None and self._conn is not None:
            with contextlib.suppress(Exception):
                self._loop.remove_reader(self._conn.fileno())
        self._out.put(("stop",))
        self._out.put(None)  # ends the sender
        for task in list(self._tasks):
            task.cancel()
        if self._proc is not None:
            await asyncio.to_thread(self._proc.join, 30.0)
            if self._proc.is_alive():
                log.error("OPC UA server process did not stop: killing it")
                self._proc.kill()
                await asyncio.to_thread(self._proc.join, 10.0)
        if self._sender is not None:
            await asyncio.to_thread(self._sender.join, 10.0)
        if self._conn is not None:
            self._conn.close()
        self._proc = self._conn = self._sender = None

    # -- the pipe ---------------------------------------------------------------------------
    def _send_loop(self) -> None:
        while True:
            msg = self._out.get()
            if msg is None:
                return
            try:
                self._conn.send(msg)
            except (OSError, ValueError, EOFError):  # the child is gone
                return

    def _on_snapshot(self, snap: Snapshot) -> None:
        self._out.put(("snap", snap))

    def _on_readable(self) -> None:
        conn = self._conn
        try:
            while conn is not None and conn.poll():
                self._handle(conn.recv())
        except (EOFError, OSError):
            assert self._loop is not None
            self._loop.remove_reader(conn.fileno())
            self._settle(RuntimeError("the OPC UA server process ended"))
            if self.ready:
                log.error("OPC UA server process ended")
                self.error = "the OPC UA server process ended"

    def _settle(self, exc: BaseException | None) -> None:
        if self._ready is None or self._ready.done():
            return
        if exc is None:
            self._ready.set_result(None)
            return
        self.error = f"{type(exc).__name__}: {exc}"
        log.error("OPC UA server at %s did not start: %s", self.endpoint, self.error)
        self._ready.set_exception(exc)
        self._ready.exception()  # retrieved: wait_ready re-raises it

    def _handle(self, msg: Any) -> None:
        kind = msg[0]
        if kind == "ready":
            self.load_s = float(msg[1])
            self._settle(None)
        elif kind == "failed":
            self._settle(RuntimeError(str(msg[1])))
        elif kind == "req":
            assert self._loop is not None
            task = self._loop.create_task(self._answer(msg[1], msg[2], *msg[3:]))
            self._tasks.add(task)
            task.add_done_callback(self._tasks.discard)

    async def _answer(self, rid: int, what: str, *args: Any) -> None:
        try:
            if what == "refresh":
                await self.credentials.refresh()
                value: Any = self.credentials.tables()
            else:
                value = await self._command(*args)
        except Exception as exc:
            log.exception("OPC UA: request %s failed", what)
            value = ("error", repr(exc))
        self._out.put(("reply", rid, value))

    async def _command(self, name: str, who: tuple[str, int], args: tuple[Any, ...]) -> Any:
        """A method call of a signed-in user on the handshake: ``(value, error, triggers)``."""
        hs = self.handshake
        user = LinkUser(str(who[0]), Role(int(who[1])))
        value: Any
        if name == "enable":
            if int(user.role) < int(Role.operator):
                value = hs._fail(ErrorCode.ROLE_TOO_LOW, f"{user.name} may not enable triggers")
            else:
                hs.set_trigger_enable(bool(args[0]))
                value = True
        elif name == "trigger":
            value = await hs.trigger(user)
        elif name == "start_run":
            value = await hs.start_run(user, int(args[0]) or None)
        elif name == "stop_run":
            value = hs.stop_run(user)
        elif name == "reset":
            value = await hs.reset(user)
        elif name == "select":
            value = await hs.select_recipe(user, int(args[0]))
        elif name == "ack":
            value = hs.acknowledge(int(args[0]))
            hs.present_next()
        else:
            raise ValueError(f"unknown command {name!r}")
        snap = hs.snapshot
        return value, int(snap.error), snap.triggers


# -- the child process ----------------------------------------------------------------------
class Bridge:
    """The server's end of the pipe (in the child, on its event loop)."""

    def __init__(self, conn: Any, server: Any = None) -> None:
        self.conn = conn
        self.server = server
        self._ids = itertools.count(1)
        self._waiting: dict[int, asyncio.Future[Any]] = {}
        self._lock = threading.Lock()

    def send(self, msg: Any) -> None:
        with self._lock:
            self.conn.send(msg)

    async def request(self, what: str, *args: Any) -> Any:
        """Ask the cell's process; its answer (``RuntimeError`` for its failure)."""
        rid = next(self._ids)
        fut = asyncio.get_running_loop().create_future()
        self._waiting[rid] = fut
        self.send(("req", rid, what, *args))
        try:
            value = await asyncio.wait_for(fut, BOUND_S)
        finally:
            self._waiting.pop(rid, None)
        if isinstance(value, tuple) and value and value[0] == "error":
            raise RuntimeError(value[1])
        return value

    def on_readable(self) -> None:
        try:
            while self.conn.poll():
                msg = self.conn.recv()
                if msg[0] == "snap" and self.server is not None:
                    self.server.on_snapshot(msg[1])
                elif msg[0] == "reply":
                    fut = self._waiting.get(msg[1])
                    if fut is not None and not fut.done():
                        fut.set_result(msg[2])
                elif msg[0] == "stop" and self.server is not None:
                    self.server.stop_event.set()
        except (EOFError, OSError):  # the cell's process is gone
            if self.server is not None:
                self.server.stop_event.set()


def child_main(conn: Any, config: dict[str, Any]) -> None:
    """Entry point of the OPC UA server process."""
    import os

    logging.basicConfig(level=config["log_level"],
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")  # fmt: skip
    os.environ.setdefault("MUJOCO_GL", "egl")
    asyncio.run(_child(conn, config))


async def _child(conn: Any, config: dict[str, Any]) -> None:
    from backend.plc.opcua import OpcUaServer
    from backend.throttle import SignInThrottle

    bridge = Bridge(conn)
    loop = asyncio.get_running_loop()
    loop.add_reader(conn.fileno(), bridge.on_readable)
    creds = Credentials(None, config["secret"],
                        user_certificates=Path(".") if config["user_certificates"] else None)  # fmt: skip
    throttle = SignInThrottle(**config["throttle"]) if config["throttle"] else None
    server = OpcUaServer(
        bridge, creds, endpoint=config["endpoint"], anonymous_read=config["anonymous_read"],
        nodesets=[Path(p) for p in config["nodesets"]], throttle=throttle,
        security=config["security"],
        cert_dir=None if config["cert_dir"] is None else Path(config["cert_dir"]),
    )  # fmt: skip
    bridge.server = server
    try:
        await server.serve(lambda load_s: bridge.send(("ready", load_s)))
    except BaseException as exc:
        log.exception("OPC UA server failed")
        with contextlib.suppress(Exception):
            bridge.send(("failed", f"{type(exc).__name__}: {exc}"))
        raise
