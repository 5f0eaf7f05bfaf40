"""The load generator's lean HTTP/1.1 client against a scripted server: framings,
keep-alive, reconnects and malformed answers."""

from __future__ import annotations

import asyncio
from collections.abc import Callable

import pytest

from benchmarks.leanhttp import HttpError, LeanConnection


async def _serve(answer: Callable[[bytes], bytes], keep_open: bool = True):
    """A server answering each request head with ``answer(head)``; counts connections."""
    conns: list[int] = []

    async def handle(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        conns.append(1)
        try:
            while True:
                head = await reader.readuntil(b"\r\n\r\n")
                writer.write(answer(head))
                await writer.drain()
                if not keep_open:
                    break
        except (asyncio.IncompleteReadError, ConnectionError):
            pass
        writer.close()

    server = await asyncio.start_server(handle, "127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    return server, f"http://127.0.0.1:{port}", conns


def test_keep_alive_content_length_and_chunked() -> None:
    def answer(head: bytes) -> bytes:
        assert b"Authorization: Bearer T\r\n" in head
        if head.startswith(b"GET /chunked "):
            return b"HTTP/1.1 200 OK\r\ntransfer-encoding: chunked\r\n\r\n3\r\nabc\r\n2\r\nde\r\n0\r\n\r\n"
        return b"HTTP/1.1 404 Not Found\r\ncontent-length: 4\r\n\r\nnope"

    async def run() -> None:
        server, base, conns = await _serve(answer)
        c = LeanConnection(base, headers={"Authorization": "Bearer T"}, timeout_s=5)
        try:
            assert await c.get("/chunked") == (200, b"abcde")
            assert await c.get("/x?limit=2") == (404, b"nope")
            assert await c.get("/chunked") == (200, b"abcde")
            assert len(conns) == 1  # one keep-alive connection for all three
        finally:
            await c.close()
            server.close()

    asyncio.run(run())


def test_connection_close_reconnects() -> None:
    def answer(head: bytes) -> bytes:
        return b"HTTP/1.1 200 OK\r\ncontent-length: 2\r\nconnection: close\r\n\r\nok"

    async def run() -> None:
        server, base, conns = await _serve(answer, keep_open=False)
        c = LeanConnection(base, headers={}, timeout_s=5)
        try:
            for _ in range(3):
                assert await c.get("/") == (200, b"ok")
            assert len(conns) == 3
        finally:
            await c.close()
            server.close()

    asyncio.run(run())


@pytest.mark.parametrize(
    "raw",
    [
        b"SMTP 220 hello\r\n\r\n",
        b"HTTP/1.1 abc OK\r\n\r\n",
        b"HTTP/1.1 200 OK\r\ncontent-length: -1\r\n\r\n",
        b"HTTP/1.1 200 OK\r\ntransfer-encoding: chunked\r\n\r\nzz\r\n",
    ],
)
def test_malformed_answers_raise_http_error(raw: bytes) -> None:
    async def run() -> None:
        server, base, _ = await _serve(lambda head: raw)
        c = LeanConnection(base, headers={}, timeout_s=5)
        try:
            with pytest.raises(HttpError):
                await c.get("/")
        finally:
            await c.close()
            server.close()

    asyncio.run(run())


def test_timeout_and_refused_raise_http_error() -> None:
    async def run() -> None:
        server, base, _ = await _serve(lambda head: b"")  # never answers
        c = LeanConnection(base, headers={}, timeout_s=0.3)
        try:
            with pytest.raises(HttpError, match="TimeoutError"):
                await c.get("/")
        finally:
            await c.close()
            server.close()
            await server.wait_closed()
        with pytest.raises(HttpError):
            await LeanConnection(base, headers={}, timeout_s=2).get("/")

    asyncio.run(run())


def test_bad_arguments_are_refused() -> None:
    with pytest.raises(ValueError, match="base"):
        LeanConnection("https://x:1", headers={}, timeout_s=1)
    with pytest.raises(ValueError, match="timeout_s"):
        LeanConnection("http://x:1", headers={}, timeout_s=float("nan"))
    with pytest.raises(ValueError, match="header"):
        LeanConnection("http://x:1", headers={"a": "b\r\nc: d"}, timeout_s=1)
    c = LeanConnection("http://x:1", headers={}, timeout_s=1)
    with pytest.raises(ValueError, match="target"):
        asyncio.run(c.get("no-slash"))
