"""Pieces of the fault campaign (``benchmarks/faultkit.py``): the TCP proxy that makes a
PostgreSQL database unreachable without touching the server, and the judgement of the
motion audit log against the faults injected."""

from __future__ import annotations

import asyncio
import socket

import pytest

from benchmarks.faultkit import FaultWindow, TcpProxy, judge_motions


def _echo_server() -> tuple[socket.socket, int]:
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen()
    return srv, int(srv.getsockname()[1])


def test_proxy_forwards_refuses_when_cut_and_comes_back():
    async def main() -> None:
        srv, port = _echo_server()
        loop = asyncio.get_running_loop()

        async def echo_once() -> None:
            conn, _ = await loop.sock_accept(srv)
            data = await loop.sock_recv(conn, 100)
            await loop.sock_sendall(conn, data.upper())
            await loop.sock_recv(conn, 100)  # wait for the close
            conn.close()

        proxy = TcpProxy("127.0.0.1", port)
        pport = await asyncio.to_thread(proxy.start)
        try:
            task = asyncio.create_task(echo_once())
            r, w = await asyncio.open_connection("127.0.0.1", pport)
            w.write(b"ping")
            assert await asyncio.wait_for(r.read(4), 5) == b"PING"
            await asyncio.to_thread(proxy.cut)  # the open connection is dropped ...
            assert await asyncio.wait_for(r.read(), 5) == b""
            with pytest.raises(OSError):  # ... and new ones are refused
                await asyncio.open_connection("127.0.0.1", pport)
            w.close()
            await task
            await asyncio.to_thread(proxy.restore)
            task = asyncio.create_task(echo_once())
            r, w = await asyncio.open_connection("127.0.0.1", pport)
            w.write(b"back")
            assert await asyncio.wait_for(r.read(4), 5) == b"BACK"
            w.close()
            await task
        finally:
            await asyncio.to_thread(proxy.stop)
            srv.close()

    asyncio.run(main())


def _move(t, **kw):
    m = {"t": t, "pid": 1, "seq": int(t), "q0": [0.0] * 5, "estopped": False,
         "connected": True, "lock": "job 1", "within_limits": True,
         "end": {"q": [0.1] + [0.0] * 4, "completed": True}}  # fmt: skip
    m.update(kw)
    return m


def test_motions_are_judged_against_state_and_fault_windows():
    windows = [FaultWindow("estop", 10.0, 20.0), FaultWindow("database", 30.0, 40.0)]
    not_moved = {"q": [0.0] * 5, "error": "RobotBusy: emergency stop is active"}
    moves = [
        _move(1.0),  # fine
        _move(2.0, lock=None),  # nobody held the motion lock
        _move(3.0, within_limits=False),
        _move(12.0, end=not_moved),  # commanded in the e-stop, refused: did not move
        _move(15.0),  # moved while the e-stop was pressed
        _move(16.0, end=None),  # its process died mid-move: assumed moved
        _move(35.0),  # the inspection under way moved during a database outage
    ]
    j = judge_motions(moves, windows)
    assert j["none"]["audited"] == 3 and len(j["none"]["unsafe"]) == 2, j["none"]
    assert j["estop"]["audited"] == 3 and j["estop"]["during_fault"] == 3
    assert len(j["estop"]["unsafe"]) == 2 and all("moved during" in u for u in j["estop"]["unsafe"])
    assert j["database"] == {"audited": 1, "unsafe": [], "during_fault": 1}
