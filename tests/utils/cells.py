"""A cell on the ideal driver with a scripted camera, for tests of the building blocks."""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from backend.cell import Cell
from backend.settings import Settings
from robot.drivers.ideal import IdealDriver
from vision.errors import CameraError
from vision.sources import Frame


class ScriptedCamera:
    """Frames of 32 x 24 pixels, stamped at grab, recording the arm's state at exposure.

    ``fail`` is a list of exceptions raised by the next grabs (then frames again); ``opens``
    counts successful opens.
    """

    name = "scripted"

    def __init__(self, driver: Any = None) -> None:
        self.driver = driver
        self.fail: list[BaseException] = []
        self.fail_open: list[BaseException] = []
        self.opens = 0
        self.closes = 0
        self.count = 0
        self.is_open = False

    async def open(self) -> None:
        if self.fail_open:
            raise self.fail_open.pop(0)
        self.opens += 1
        self.is_open = True

    async def close(self) -> None:
        self.closes += 1
        self.is_open = False

    async def grab(self) -> Frame:
        if not self.is_open:
            raise CameraError("not open")
        if self.fail:
            raise self.fail.pop(0)
        state = self.driver.state if self.driver is not None else None
        rgb = np.full((24, 32, 3), self.count % 256, np.uint8)
        frame = Frame(
            rgb=rgb,
            stamp_s=time.monotonic(),
            index=self.count,
            meta={"moving": None if state is None else state.moving,
                  "q": None if state is None else tuple(state.q)},
        )  # fmt: skip
        self.count += 1
        return frame


def ideal_cell(settings: Settings, **kw: Any) -> tuple[Cell, IdealDriver, ScriptedCamera]:
    """A :class:`Cell` on an :class:`IdealDriver` running ``settings.time_scale`` and a
    :class:`ScriptedCamera` that sees the driver's state (not started)."""
    driver = IdealDriver(rate_hz=100.0, time_scale=settings.time_scale)
    camera = ScriptedCamera(driver)
    return Cell(settings, driver, camera, **kw), driver, camera
