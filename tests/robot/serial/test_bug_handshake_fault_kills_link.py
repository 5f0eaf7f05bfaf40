"""Bug: a fault during the reconnect handshake could leave the serial link dead for good.

``python -m benchmarks.serial`` stalled (``campaign stalled: no fault injected for 60 s``,
after ``Task exception was never retrieved ... SerialDriver._handshake ... CommandTimeout: no
reply to RATE``).  The chain, reproduced here over a real pseudo-terminal:

1. a ``GET_STATE`` is on the wire when the port vanishes; the session is resumed on
   reconnection, so the handshake re-sends it, and its reply published ``connected=True``
   while the handshake was still running (``RATE`` not yet answered);
2. a host that waits for ``state.connected`` before moving (the campaign does) then got
   ``LinkDown`` at once, without yielding to the event loop: it spun, the loop starved, no
   timer fired, the link stayed dead;
3. when the driver was closed during a handshake, the handshake task was orphaned and its
   exception never retrieved.

The state must never claim a link the driver cannot use, a failed handshake must lead to
another attempt, and closing the driver must leave no task behind.
"""

import asyncio
import gc

import pytest

from robot.drivers.serial import FaultConfig, SerialDriver
from robot.drivers.serial.frames import GetState
from robot.model import ASEA


async def _until(pred, timeout_s=8.0):
    async with asyncio.timeout(timeout_s):
        while not pred():
            await asyncio.sleep(0.01)


@pytest.fixture
async def loop_errors():
    """Exceptions the event loop reports (``Task exception was never retrieved`` and the like)."""
    loop = asyncio.get_running_loop()
    errors: list[dict] = []
    previous = loop.get_exception_handler()
    loop.set_exception_handler(lambda _loop, ctx: errors.append(ctx))
    yield errors
    loop.set_exception_handler(previous)


async def test_fault_during_handshake_leads_to_another_reconnect(
    emulator, make_driver, loop_errors
):
    emu = emulator
    d: SerialDriver = make_driver(emu.path, command_timeout_s=2.0)
    await d.connect()
    assert d.state.connected
    seen: list[tuple[bool, str]] = []

    async def watch():
        async for s in d.states():
            seen.append((s.connected, s.fault))

    watcher = asyncio.create_task(watch())
    await asyncio.sleep(0.05)

    # 1. A GET_STATE on the wire when the port vanishes (the controller is slow to answer).
    emu.fault = FaultConfig(process_delay_s=0.3)
    n_state = sum(isinstance(c, GetState) for c in emu.received)
    reset = asyncio.create_task(d.reset())
    await _until(lambda: sum(isinstance(c, GetState) for c in emu.received) > n_state)
    # 2. The handshake after the outage loses every answer to RATE: it must fail ...
    emu.fault = FaultConfig(mute_replies=("RATE",))
    await emu.vanish(0.2)
    await _until(lambda: "handshake failed" in d.state.fault)
    assert "RATE" in d.state.fault
    await reset  # the re-sent GET_STATE was answered from the controller's cache
    # 3. ... and the next attempt, on a clean line, must bring the link back.
    emu.fault = FaultConfig()
    await _until(lambda: d.state.connected)
    assert await d.ping() > 0
    report = await d.move_joints(ASEA.q_ready, speed=1.0)
    assert report.completed, report.reason
    watcher.cancel()

    # The state never said "connected" between the loss and the successful handshake:
    # exactly one fall and one rise, however many attempts it took.
    flips = [c for i, (c, _) in enumerate(seen) if i == 0 or c != seen[i - 1][0]]
    assert flips == [True, False, True], seen
    assert d.outages == 1
    assert not loop_errors, loop_errors


async def test_close_during_a_handshake_leaves_no_task_behind(emulator, loop_errors):
    emu = emulator
    emu.fault = FaultConfig(mute_replies=("RATE",))  # every handshake hangs on RATE
    d = SerialDriver(emu.path, command_timeout_s=5.0, connect_timeout_s=0.3, seed=1)
    await d.connect()  # returns after 0.3 s with the handshake still waiting for RATE
    assert not d.state.connected
    assert any("handshake" in repr(t.get_coro()) for t in asyncio.all_tasks())
    await d.close()
    await asyncio.sleep(0.05)
    leftover = [
        t for t in asyncio.all_tasks() - {asyncio.current_task()}
        if "serial" in repr(t.get_coro()) or "handshake" in repr(t.get_coro())
    ]  # fmt: skip
    assert not leftover, leftover
    gc.collect()
    await asyncio.sleep(0)
    assert not loop_errors, loop_errors
