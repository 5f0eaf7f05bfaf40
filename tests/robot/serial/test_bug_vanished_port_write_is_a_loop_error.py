"""Bug: a write to a vanished port was reported to the event loop as an unhandled error.

When the port goes (the emulator's PTY closed, a USB adapter pulled), pyserial-asyncio ends
the connection quietly if its read sees the fault first, but through the loop's exception
handler ("Fatal write error on serial transport") if its write does: a routine outage logged
as a crash one time in a few, depending on which callback the loop ran first (CI failed
``test_fault_during_handshake_leads_to_another_reconnect`` on it under load).  Here the
reader is paused so the write is certain to meet the fault first.
"""

from __future__ import annotations

import asyncio
import os
import tty

import pytest

from robot.drivers.serial.transport import SerialLink
from robot.errors import LinkDown


async def test_a_write_into_a_vanished_port_ends_the_link_quietly():
    loop = asyncio.get_running_loop()
    errors: list[dict] = []
    previous = loop.get_exception_handler()
    loop.set_exception_handler(lambda _loop, ctx: errors.append(ctx))
    master, slave = os.openpty()
    tty.setraw(master)
    try:
        link = await SerialLink.open(os.ttyname(slave), baud=115200, on_bytes=lambda b: None)
        os.close(slave)
        assert link._transport is not None
        link._transport.pause_reading()  # the write, not the read, meets the fault
        os.close(master)
        master = -1
        link.write(b"PING\n")
        exc = await asyncio.wait_for(link.closed, 5.0)
        assert isinstance(exc, OSError), exc  # the reason reaches the layers above
        assert not link.is_open
        with pytest.raises(LinkDown):
            link.write(b"PING\n")
        await asyncio.sleep(0.05)
        assert not errors, errors
    finally:
        loop.set_exception_handler(previous)
        if master >= 0:
            os.close(master)
