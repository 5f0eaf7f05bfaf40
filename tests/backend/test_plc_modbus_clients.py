"""The Modbus TCP server serves at most ``max_clients`` connections: one more is closed as it
arrives, the others go on answering, and a closed connection frees its place."""

from __future__ import annotations

import asyncio
from types import SimpleNamespace

import pytest

from backend.cell.events import EventBus
from backend.db.models import Role
from backend.plc.handshake import Handshake
from backend.plc.modbus import MAX_CLIENTS, ModbusLink
from tests.utils.factories import free_port

#: Read holding register 0 of device 0 (transaction 1): MBAP header, then the PDU.
READ = bytes([0, 1, 0, 0, 0, 6, 0, 3, 0, 0, 0, 1])
#: Bounds that only end a hang.
HANG_S = 30.0


async def _answers(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> bool:
    writer.write(READ)
    await writer.drain()
    head = await asyncio.wait_for(reader.readexactly(11), HANG_S)  # and the register
    return head[7] == 3 and head[8] == 2  # function 3, two bytes of register


async def _closed(reader: asyncio.StreamReader) -> bool:
    return await asyncio.wait_for(reader.read(1), HANG_S) == b""


def test_connections_beyond_the_cap_are_closed_and_a_freed_place_is_reused() -> None:
    async def main() -> None:
        rt = SimpleNamespace(bus=EventBus(), cell=SimpleNamespace(estopped=False), sim=None)
        hs = Handshake(rt, name="modbus")
        await hs.start()
        port = free_port()
        link = ModbusLink(hs, host="127.0.0.1", port=port, role=Role.operator, max_clients=2)
        await link.start()
        try:
            a = await asyncio.open_connection("127.0.0.1", port)
            b = await asyncio.open_connection("127.0.0.1", port)
            assert await _answers(*a) and await _answers(*b)
            c = await asyncio.open_connection("127.0.0.1", port)
            assert await _closed(c[0])  # the third is refused
            assert await _answers(*a) and await _answers(*b)  # the two go on
            a[1].close()
            await a[1].wait_closed()
            for _ in range(100):  # the server learns of the close (a bound on a hang)
                d = await asyncio.open_connection("127.0.0.1", port)
                try:
                    if await _answers(*d):
                        break
                except (asyncio.IncompleteReadError, ConnectionError):
                    await asyncio.sleep(0.05)
            else:
                raise AssertionError("a freed place was never given to a new connection")
            assert await _answers(*b)
            for _r, w in (b, c, d):
                w.close()
        finally:
            await link.stop()
            await hs.stop()

    asyncio.run(main())


@pytest.mark.parametrize("bad", [0, MAX_CLIENTS + 1, True, 2.0])
def test_the_cap_is_bounded(bad) -> None:
    rt = SimpleNamespace(bus=EventBus(), cell=SimpleNamespace(estopped=False), sim=None)
    with pytest.raises(ValueError, match="max_clients"):
        ModbusLink(Handshake(rt, name="m"), host="127.0.0.1", port=5020, role=Role.operator,
                   max_clients=bad)  # fmt: skip
