"""An emulated serial controller on a pseudo-terminal, on its own loop and thread."""

from __future__ import annotations

import asyncio
import contextlib
import threading
from collections.abc import Iterator
from pathlib import Path

from robot.drivers.ideal import IdealDriver
from robot.drivers.serial.emulator import run_emulator


@contextlib.contextmanager
def emulated_controller(folder: Path, *, time_scale: float = 10.0) -> Iterator[str]:
    """Serve an emulated controller (an ideal arm at ``time_scale``) on a PTY linked at
    ``folder/robot-tty``; yields the link's path, stops the emulator after."""
    link = str(folder / "robot-tty")
    ready = threading.Event()
    loop = asyncio.new_event_loop()
    box: dict[str, asyncio.Event] = {}

    async def serve() -> None:
        box["stop"] = asyncio.Event()
        await run_emulator(
            IdealDriver(time_scale=time_scale), link=link, announce=lambda _: ready.set(),
            stop=box["stop"],
        )  # fmt: skip

    thread = threading.Thread(target=loop.run_until_complete, args=(serve(),), daemon=True)
    thread.start()
    if not ready.wait(60):
        raise RuntimeError("the emulator did not start")
    try:
        yield link
    finally:
        loop.call_soon_threadsafe(box["stop"].set)
        thread.join(30)
