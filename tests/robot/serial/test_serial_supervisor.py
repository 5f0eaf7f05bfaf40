"""The link supervisor: backoff doubles to its cap with jitter, and starts over after a success."""

import asyncio
import random

from robot.backoff import Backoff
from robot.drivers.serial import LinkSupervisor, SerialDevice
from robot.drivers.serial.emulator import Emulator
from robot.drivers.serial.frames import Hello


class RecordingBackoff(Backoff):
    """Records every delay (no jitter, so the wait is the delay) and waits only 10 ms."""

    def __init__(self, **kw):
        super().__init__(jitter=(1.0, 1.0), **kw)
        self.delays: list[float] = []

    def next_delay(self):
        self.delays.append(super().next_delay())
        return 0.01


def make(path, device, backoff=None):
    async def handshake():
        await device.request(lambda s: Hello(s, "0000BEEF"), timeout_s=1.0, urgent=True)
        device.set_ready(resumed=False)

    backoff = backoff or Backoff(initial_s=0.05, max_s=0.4, rng=random.Random(1))
    return LinkSupervisor(
        path, baud=115200, device=device, handshake=handshake, on_down=lambda why: None,
        heartbeat_s=0.1, silence_timeout_s=5.0, command_timeout_s=1.0, backoff=backoff,
    )  # fmt: skip


def test_jittered_wait_stays_within_half_and_full_delay():
    sup = make("/nonexistent", SerialDevice(lambda e: None))
    waits = []
    for _ in range(500):
        sup.backoff.reset()
        for _ in range(3):  # 0.05, 0.1, 0.2: the third delay is 0.2
            wait = sup.backoff.next_delay()
        waits.append(wait)
    assert 0.1 <= min(waits) < 0.11 and 0.19 < max(waits) <= 0.2
    for _ in range(5):
        sup.backoff.next_delay()
    assert sup.backoff.next_delay() <= 0.4  # doubling is capped


async def test_backoff_doubles_then_resets_after_a_successful_connection(ideal, tmp_path):
    path = str(tmp_path / "tty")
    device = SerialDevice(lambda e: None)
    backoff = RecordingBackoff(initial_s=0.05, max_s=0.4)
    sup = make(path, device, backoff)
    sup.start()
    try:
        async with asyncio.timeout(3.0):
            while len(backoff.delays) < 6:
                await asyncio.sleep(0.005)
        assert backoff.delays[:6] == [0.05, 0.1, 0.2, 0.4, 0.4, 0.4]
        async with Emulator(ideal, link=path) as emu:
            assert await sup.wait_ready(3.0)
            before = len(backoff.delays)
            await emu.vanish(0.15)
            assert await sup.wait_ready(3.0)
            assert backoff.delays[before] == 0.05  # the schedule started over
            assert sup.outages == 2
    finally:
        await sup.stop()
        await device.close()
    assert not await sup.wait_ready(0.1)
