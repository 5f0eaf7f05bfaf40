"""3D scene recordings of inspections: viser's scene serializer.

While an object is inspected, :class:`SceneRecorder` holds a
``viser.ViserServer.get_scene_serializer()`` handle: it starts with a snapshot of the scene
(arm, belt, objects, camera frustum) and then receives every scene message the 3D view sends
(the arm's joint updates, the frustum image, the inspection's markers).  A clock task inserts
the real time between messages (``insert_sleep``), so the ``.viser`` bytes replay at the
speed of the inspection in viser's client (``?playbackPath=``).

Bounded: recording stops after :data:`MAX_SCENE_S` seconds (later messages are not kept),
and a recording larger than :data:`MAX_SCENE_BYTES` once serialized is dropped (the
inspection is then stored without a scene, and the log says why).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from typing import Any

from sqlalchemy import select
from sqlalchemy.ext.asyncio import AsyncSession

from backend.db.models import Inspection, InspectionScene
from vision.errors import NotFound

__all__ = [
    "CLOCK_S",
    "MAX_SCENE_BYTES",
    "MAX_SCENE_S",
    "SceneRecorder",
    "read_scene",
]

log = logging.getLogger(__name__)

#: Longest recording, s (an inspection takes a few seconds; a continuous run waits at most
#: ``wait_s`` for the object, which is not worth replaying).
MAX_SCENE_S = 120.0
#: Largest stored recording, bytes.
MAX_SCENE_BYTES = 16 * 1024 * 1024
#: Period of the recording clock, s.
CLOCK_S = 0.05


class SceneRecorder:
    """Record the scene of a running viser server from now until :meth:`finish`.

    Parameters
    ----------
    server : viser.ViserServer or None
        The 3D view's server; None (no 3D view) records nothing.
    max_s, max_bytes : float, int
        Bounds (module docstring).
    """

    def __init__(self, server: Any, *, max_s: float = MAX_SCENE_S,
                 max_bytes: int = MAX_SCENE_BYTES) -> None:  # fmt: skip
        if not (0.0 < max_s <= 3600.0):
            raise ValueError(f"max_s must be in (0, 3600] s, got {max_s!r}")
        if not 0 < max_bytes <= 2**31:
            raise ValueError(f"max_bytes must be in 1..2^31, got {max_bytes!r}")
        self.max_s = float(max_s)
        self.max_bytes = int(max_bytes)
        self._ser: Any = None
        self._task: asyncio.Task[None] | None = None
        self._done = False
        self._clock = 0.0
        self.note = ""
        if server is not None:
            self._ser = server.get_scene_serializer()
            self._t0 = time.monotonic()
            self._task = asyncio.get_running_loop().create_task(self._tick())

    @property
    def recording(self) -> bool:
        """Whether messages are being recorded."""
        return self._ser is not None and not self._done

    def _advance(self) -> None:
        now = min(time.monotonic() - self._t0, self.max_s)
        if now > self._clock:
            self._ser.insert_sleep(now - self._clock)
            self._clock = now

    async def _tick(self) -> None:
        while True:
            await asyncio.sleep(CLOCK_S)
            self._advance()
            if self._clock >= self.max_s:
                # Stop receiving messages: serialize now, keep the bytes for finish().
                self._bytes = self._close()
                return

    def _close(self) -> bytes | None:
        if self._ser is None or self._done:
            return None
        self._done = True
        data: bytes = self._ser.serialize()
        return data

    async def finish(self) -> bytes | None:
        """Stop and return the recording (None: no 3D view, or larger than ``max_bytes``)."""
        if self._ser is None:
            return None
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
        if self._done:
            data = getattr(self, "_bytes", None)
        else:
            self._advance()
            data = self._close()
        if data is not None and len(data) > self.max_bytes:
            self.note = f"scene of {len(data)} bytes is larger than {self.max_bytes}: not stored"
            log.warning(self.note)
            return None
        return data

    async def abandon(self) -> None:
        """Stop recording and drop what was recorded."""
        await self.finish()


async def read_scene(
    session: AsyncSession, inspection_id: int, cell_id: int | None = None
) -> bytes:
    """The recording of one inspection, or :class:`NotFound`.

    With ``cell_id`` only an inspection of that cell is found: a plant's cells share one
    database, and another cell's scene is as unreadable here as its row.
    """
    q = select(InspectionScene.scene).where(InspectionScene.inspection_id == inspection_id)
    if cell_id is not None:
        q = q.join(Inspection, Inspection.id == InspectionScene.inspection_id).where(
            Inspection.cell_id == cell_id
        )
    data = await session.scalar(q)
    if data is None:
        raise NotFound(f"inspection {inspection_id} has no recorded 3D scene")
    return bytes(data)
