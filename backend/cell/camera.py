"""Camera acquisition under a supervisor: a latest-frame slot, fresh frames on demand.

One task per cell grabs frames into a single slot (never a growing queue).  Whatever goes
wrong (a :class:`~vision.errors.CameraError`, an ``OSError``, or any other exception from a
driver), the task survives: the camera is closed, the failure shows in
:meth:`CameraFeed.status` (``ok: false`` with ``Type: message``), and it is opened again
after a wait from :class:`robot.backoff.Backoff` (exponential, with jitter).  The frame rate
drops to ``idle_fps`` while nobody reads frames.

:meth:`CameraFeed.next_frame` waits for a frame exposed strictly after a given time, which is
how the cell's ``look`` gets an image that was taken after the arm stopped (never a stale
one).  JPEGs are encoded once per frame, keyed by the frame's index in this feed (the
count of frames acquired: a source's own index may start again after a reconnect).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from collections.abc import Callable

import cv2

from backend.cell.events import CameraStatus
from robot.backoff import Backoff
from vision.errors import CameraError
from vision.sources import Camera, Frame

__all__ = ["CameraFeed"]

log = logging.getLogger(__name__)

#: How long a read keeps the camera at its full rate, seconds.
DEMAND_S = 2.0
#: Longest wait for one fresh frame, seconds.
MAX_WAIT_S = 120.0
#: Longest time one ``grab()`` may take before the camera counts as stalled, seconds.
GRAB_TIMEOUT_S = 10.0


class CameraFeed:
    """The acquisition task of one camera.

    Parameters
    ----------
    camera : Camera
        Opened and re-opened by the task.
    fps, idle_fps : float
        Rate while frames are read, and while nobody has read one for :data:`DEMAND_S`.
    backoff : Backoff, optional
        Waits between failed attempts (default: 0.5 s doubling to 10 s, jitter 0.5-1).
    publish : callable, optional
        ``publish(CameraStatus)`` whenever ``ok`` or ``error`` change (the cell's bus).
    """

    def __init__(
        self,
        camera: Camera,
        *,
        fps: float,
        idle_fps: float,
        backoff: Backoff | None = None,
        publish: Callable[[CameraStatus], None] | None = None,
    ) -> None:
        for name, v in (("fps", fps), ("idle_fps", idle_fps)):
            if isinstance(v, bool) or not (isinstance(v, int | float) and 0 < v <= 1000):
                raise ValueError(f"{name} must be in (0, 1000] frames/s, got {v!r}")
        self.camera = camera
        self.fps = float(fps)
        self.idle_fps = float(idle_fps)
        self.backoff = backoff or Backoff(initial_s=0.5, max_s=10.0)
        self._publish = publish
        self._frame: Frame | None = None
        self._jpeg: tuple[int, int, bytes] | None = None  # (feed index, quality, bytes)
        self._frames = 0
        self._dt = 0.0
        self._error = ""
        self._task: asyncio.Task[None] | None = None
        self._demand_until = 0.0
        self._wake = asyncio.Event()
        self._new = asyncio.Condition()
        self._last_status: tuple[bool, str] | None = None

    # -- life cycle ----------------------------------------------------------------------
    def start(self) -> None:
        """Start the acquisition task (idempotent)."""
        if self._task is None or self._task.done():
            self._task = asyncio.create_task(self._run(), name=f"camera-{self.camera.name}")

    async def stop(self) -> None:
        """Stop the task and close the camera."""
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None
        with contextlib.suppress(Exception):
            await self.camera.close()

    @property
    def failing(self) -> str:
        """The camera's last error while it is failing (empty when frames come)."""
        return self._error

    @property
    def running(self) -> bool:
        """Whether the task is alive."""
        return self._task is not None and not self._task.done()

    # -- the supervised loop -----------------------------------------------------------------
    def note_demand(self) -> None:
        """Someone reads frames: acquire at the full rate for the next :data:`DEMAND_S`."""
        now = time.monotonic()
        if now >= self._demand_until:
            self._wake.set()  # end an idle wait at once
        self._demand_until = now + DEMAND_S

    async def _run(self) -> None:
        opened = False
        t_last = time.monotonic()
        while True:
            try:
                if not opened:
                    await self.camera.open()
                    opened = True
                t0 = time.monotonic()
                # A grab that never returns is a stalled camera, not a slow one.  The
                # ``asyncio.timeout`` block, not ``wait_for``: Python 3.11's wait_for can
                # swallow a cancel that lands as the grab completes, and the feed then
                # never stops (the e-stop conveyor test hung in cell.stop()).
                try:
                    async with asyncio.timeout(GRAB_TIMEOUT_S):
                        frame = await self.camera.grab()
                except TimeoutError:
                    raise CameraError(
                        f"camera stalled: no frame within {GRAB_TIMEOUT_S:g} s"
                    ) from None
                if not isinstance(frame, Frame):
                    raise CameraError(f"grab() returned {type(frame).__name__}, not a Frame")
                now = time.monotonic()
                dt, t_last = now - t_last, now
                # Average the interval, not its inverse (an average of 1/dt is biased upward).
                self._dt = dt if self._dt == 0.0 else 0.9 * self._dt + 0.1 * dt
                self._frame = frame
                self._frames += 1
                if self._error:
                    log.info("camera %s: frames again", self.camera.name)
                self._error = ""
                self.backoff.reset()
                self._status_changed()
                async with self._new:
                    self._new.notify_all()
                busy = time.monotonic() < self._demand_until
                period = 1.0 / (self.fps if busy else self.idle_fps)
                self._wake.clear()
                with contextlib.suppress(TimeoutError):
                    async with asyncio.timeout(max(0.0, period - (time.monotonic() - t0))):
                        await self._wake.wait()
            except asyncio.CancelledError:
                raise
            except Exception as exc:  # the supervisor survives anything a driver raises
                text = f"{type(exc).__name__}: {exc}"
                if text != self._error:
                    log.warning("camera %s failed: %s", self.camera.name, text)
                self._error = text
                opened = False
                with contextlib.suppress(Exception):
                    await self.camera.close()
                self._dt = 0.0
                self._status_changed()
                async with self._new:
                    self._new.notify_all()  # waiters see the error at once
                await self.backoff.sleep()
                t_last = time.monotonic()

    def _status_changed(self) -> None:
        key = (self._frame is not None and not self._error, self._error)
        if key != self._last_status:
            self._last_status = key
            if self._publish is not None:
                try:
                    self._publish(self.status())
                except Exception:
                    log.exception("publishing the camera status failed")

    # -- readers -------------------------------------------------------------------------
    @property
    def latest(self) -> Frame | None:
        """The newest frame (None before the first); reading keeps the full rate."""
        self.note_demand()
        return self._frame

    async def next_frame(self, *, after: float, timeout_s: float = 10.0) -> Frame:
        """The first frame exposed strictly after ``after`` (``time.monotonic()`` seconds).

        Raises :class:`~vision.errors.CameraError` with the camera's last error when none
        arrives within ``timeout_s``.
        """
        if (
            isinstance(after, bool)
            or not isinstance(after, int | float)
            or not math.isfinite(after)
        ):
            raise ValueError(f"after must be a finite time.monotonic() value, got {after!r}")
        if isinstance(timeout_s, bool) or not 0.0 < float(timeout_s) <= MAX_WAIT_S:
            raise ValueError(f"timeout_s must be in (0, {MAX_WAIT_S:g}] s, got {timeout_s!r}")
        deadline = time.monotonic() + float(timeout_s)
        async with self._new:
            while True:
                self.note_demand()
                frame = self._frame
                if frame is not None and frame.stamp_s > after:
                    return frame
                left = deadline - time.monotonic()
                if left <= 0.0:
                    raise CameraError(
                        f"the camera {self.camera.name!r} gave no frame exposed after the "
                        f"request within {float(timeout_s):g} s: "
                        f"{self._error or 'no error reported'}"
                    )
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(self._new.wait(), left)

    def latest_jpeg(self, *, quality: int = 80, demand: bool = True) -> bytes | None:
        """The newest frame as JPEG, encoded once per frame (keyed by its index).

        With ``demand=False`` it does not touch the event loop's objects, so it may run in a
        worker thread (call :meth:`note_demand` on the loop first)."""
        if isinstance(quality, bool) or not isinstance(quality, int) or not 1 <= quality <= 100:
            raise ValueError(f"quality must be an int in [1, 100], got {quality!r}")
        if demand:
            self.note_demand()
        frame = self._frame
        if frame is None:
            return None
        seq = self._frames  # the feed's index of the frame in the slot
        cached = self._jpeg
        if cached is None or cached[0] != seq or cached[1] != quality:
            ok, buf = cv2.imencode(
                ".jpg",
                cv2.cvtColor(frame.rgb, cv2.COLOR_RGB2BGR),
                [cv2.IMWRITE_JPEG_QUALITY, quality],
            )
            if not ok:
                return None
            cached = self._jpeg = (seq, quality, buf.tobytes())
        return cached[2]

    def encoded_jpeg(self, *, quality: int = 80) -> bytes | None:
        """The newest frame's JPEG if :meth:`latest_jpeg` has encoded it already at this
        ``quality`` (None: it needs encoding, or there is no frame); never encodes."""
        cached = self._jpeg
        if self._frame is None or cached is None:
            return None
        return cached[2] if cached[0] == self._frames and cached[1] == quality else None

    def status(self) -> CameraStatus:
        """Name, health, frame count, rate and last error of the camera."""
        return CameraStatus(
            name=self.camera.name,
            ok=self._frame is not None and not self._error and self.running,
            frames=self._frames,
            fps=round(1.0 / self._dt, 2) if self._dt > 0 else 0.0,
            error=self._error,
            retries=self.backoff.attempts,
        )
