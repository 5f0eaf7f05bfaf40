"""The link supervisor: backoff doubles to its cap with jitter, and starts over after a success."""

import asyncio
import random

from robot.drivers.serial import LinkSupervisor, SerialDevice
from robot.drivers.serial.emulator import Emulator
from robot.drivers.serial.frames import Hello


class RecordingSupervisor(LinkSupervisor):
    """Records the backoff delay of every failed attempt and waits only 10 ms."""

    def __init__(self, *args, **kw):
        super().__init__(*args, **kw)
        self.delays: list[float] = []

    def _backoff(self, delay):
        self.delays.append(delay)
        _, following = super()._backoff(delay)
        return 0.01, following


def make(path, device, cls=LinkSupervisor):
    async def handshake():
        await device.request(lambda s: Hello(s, "0000BEEF"), timeout_s=1.0, urgent=True)
        device.set_ready(resumed=False)

    return cls(
        path, baud=115200, device=device, handshake=handshake, on_down=lambda why: None,
        heartbeat_s=0.1, silence_timeout_s=5.0, command_timeout_s=1.0,
        backoff_initial_s=0.05, backoff_max_s=0.4, rng=random.Random(1),
    )  # fmt: skip


def test_jittered_wait_stays_within_half_and_full_delay():
    sup = make("/nonexistent", SerialDevice(lambda e: None))
    waits = [sup._backoff(0.4)[0] for _ in range(500)]
    assert 0.2 <= min(waits) < 0.22 and 0.38 < max(waits) <= 0.4
    assert sup._backoff(0.3)[1] == 0.4  # doubling is capped


async def test_backoff_doubles_then_resets_after_a_successful_connection(ideal, tmp_path):
    path = str(tmp_path / "tty")
    device = SerialDevice(lambda e: None)
    sup = make(path, device, RecordingSupervisor)
    sup.start()
    try:
        async with asyncio.timeout(3.0):
            while len(sup.delays) < 6:
                await asyncio.sleep(0.005)
        assert sup.delays[:6] == [0.05, 0.1, 0.2, 0.4, 0.4, 0.4]
        async with Emulator(ideal, link=path) as emu:
            assert await sup.wait_ready(3.0)
            before = len(sup.delays)
            await emu.vanish(0.15)
            assert await sup.wait_ready(3.0)
            assert sup.delays[before] == 0.05  # the schedule started over
            assert sup.outages == 2
    finally:
        await sup.stop()
        await device.close()
    assert not await sup.wait_ready(0.1)
