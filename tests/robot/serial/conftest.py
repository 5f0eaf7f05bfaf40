"""Fixtures for the serial link tests: an emulator on a real pseudo-terminal, a driver, a raw host."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Callable

import pytest

from robot.drivers import IdealDriver
from robot.drivers.serial import SerialDriver, SerialLink
from robot.drivers.serial.emulator import Emulator
from robot.drivers.serial.frames import Ack, Command, Event, Frame, FrameParser, Nak, encode


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "watchdog(seconds): link watchdog of the slow_cell emulator")


FAST = {
    "resend_after_s": 0.05,
    "command_timeout_s": 1.0,
    "heartbeat_s": 0.1,
    "silence_timeout_s": 0.6,
    "connect_timeout_s": 3.0,
    "reconnect_grace_s": 3.0,
    "backoff_initial_s": 0.02,
    "backoff_max_s": 0.2,
}
"""Driver timings that keep the tests quick."""


@pytest.fixture
async def ideal() -> AsyncIterator[IdealDriver]:
    d = IdealDriver(time_scale=20.0, rate_hz=100.0)
    await d.connect()
    yield d
    await d.close()


@pytest.fixture
async def emulator(ideal: IdealDriver, tmp_path) -> AsyncIterator[Emulator]:
    # The emulator shares the test's process: a stall of the process is host silence to it.
    # Its watchdog (1 s by default; tested on its own in test_serial_reconnect) is 3 s here,
    # so that a starved CI machine does not stop moves these tests are not about.
    emu = Emulator(ideal, link=str(tmp_path / "robot-tty"), rate_hz=50.0, seed=7, watchdog_s=3.0)
    await emu.start()
    yield emu
    await emu.close()


@pytest.fixture
async def make_driver() -> AsyncIterator[Callable[..., SerialDriver]]:
    """Factory of drivers with fast timings; every driver made is closed at teardown."""
    made: list[SerialDriver] = []

    def make(port: str, **kw: object) -> SerialDriver:
        d = SerialDriver(port, **{**FAST, "seed": 3, **kw})  # type: ignore[arg-type]
        made.append(d)
        return d

    yield make
    for d in made:
        await d.close()


@pytest.fixture
async def driver(emulator: Emulator) -> AsyncIterator[SerialDriver]:
    d = SerialDriver(emulator.path, **{**FAST, "seed": 3})  # type: ignore[arg-type]
    await d.connect()
    assert d.state.connected
    yield d
    await d.close()


class RawHost:
    """A bare host on the emulator's port: writes frames, collects replies and events."""

    def __init__(self) -> None:
        self.parser = FrameParser()
        self.frames: list[Frame] = []
        self.raw = bytearray()
        self.link: SerialLink | None = None
        self._arrived = asyncio.Event()

    async def open(self, path: str) -> RawHost:
        self.link = await SerialLink.open(path, baud=115200, on_bytes=self._on_bytes)
        return self

    def _on_bytes(self, data: bytes) -> None:
        self.raw += data
        self.frames.extend(self.parser.feed(data))
        self._arrived.set()

    def send(self, cmd: Command) -> bytes:
        assert self.link is not None
        wire = encode(cmd)
        self.link.write(wire)
        return wire

    def write(self, data: bytes) -> None:
        assert self.link is not None
        self.link.write(data)

    def replies(self, seq: int) -> list[Ack | Nak]:
        return [f for f in self.frames if isinstance(f, Ack | Nak) and f.seq == seq]

    @property
    def events(self) -> list[Event]:
        return [f for f in self.frames if isinstance(f, Event)]

    async def reply(self, seq: int, *, count: int = 1, timeout_s: float = 2.0) -> Ack | Nak:
        """Wait until ``count`` replies to ``seq`` arrived; return the last."""
        async with asyncio.timeout(timeout_s):
            while len(self.replies(seq)) < count:
                self._arrived.clear()
                await self._arrived.wait()
        return self.replies(seq)[-1]

    async def quiet(self, seconds: float = 0.2) -> None:
        await asyncio.sleep(seconds)

    def close(self) -> None:
        if self.link is not None:
            self.link.close()


@pytest.fixture
async def raw_host(emulator: Emulator) -> AsyncIterator[RawHost]:
    host = await RawHost().open(emulator.path)
    yield host
    host.close()
    await asyncio.sleep(0)
