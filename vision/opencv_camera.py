"""A real camera or video through ``cv2.VideoCapture``, behind the :class:`~vision.sources.Camera` protocol.

Sources
-------
- a V4L2 device index (``0`` = ``/dev/video0``) or a device path ``"/dev/videoN"``;
- a local video file (any container FFmpeg reads: ``.avi``, ``.mp4``, ...);
- a stream URL (``rtsp://``, ``http(s)://``, ``udp://``, ...).

Failure semantics (documented contract, tested in ``tests/vision/test_opencv_camera.py``)
----------------------------------------------------------------------------------------
- :meth:`OpenCVCamera.open` tries once and raises :class:`~vision.errors.CameraError` naming
  the source when it cannot be opened (a device index with no ``/dev/videoN``, a missing
  file, a stream that does not answer).  Retrying the *start* is the caller's policy.
- Live sources (devices, URLs): a failed or timed-out read releases the capture and
  reconnects with exponential backoff and jitter (``backoff_initial_s`` doubling up to
  ``backoff_max_s``, times a random factor in [0.8, 1.2]) for up to ``reconnect_attempts``
  attempts, logging one warning per outage and one info line on recovery.  When all attempts
  fail, ``grab()`` raises ``CameraError``; the next ``grab()`` starts a fresh round.
- Video files are finite: a failed read while the file is still on disk is the end of the
  stream.  With ``loop=True`` the file is rewound and replay goes on; with ``loop=False``
  ``grab()`` raises :class:`~vision.errors.StreamEnded` (a ``CameraError``), every time.
  A file that disappears is handled like a lost device (reconnect, resuming at the next frame).

Frames are converted from OpenCV's BGR (or grey) to RGB at this edge.  Every blocking OpenCV
call runs in a worker thread (``asyncio.to_thread``), so the event loop never stalls; each
capture has its own lock so that a read and a release never overlap.
"""

from __future__ import annotations

import asyncio
import logging
import random
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, Literal

import cv2
import numpy as np
from numpy.typing import NDArray

from vision.errors import CameraError, StreamEnded
from vision.sources import Frame

__all__ = ["OpenCVCamera", "SourceKind", "classify_source"]

log = logging.getLogger(__name__)

SourceKind = Literal["device", "file", "stream"]
CaptureFactory = Callable[[int | str, int, list[int]], Any]
_URL_SCHEMES = ("rtsp://", "rtsps://", "rtmp://", "http://", "https://", "udp://", "tcp://")


def classify_source(source: int | str | Path) -> tuple[SourceKind, int | str]:
    """Tell a device index/path, a video file and a stream URL apart.

    Returns the kind and the value to hand to ``cv2.VideoCapture`` (an ``int`` for devices
    given as ``3``, ``"3"`` or ``"/dev/video3"``).
    """
    if isinstance(source, bool):
        raise ValueError(f"source must be a device index, a path or a URL, got {source!r}")
    if isinstance(source, int):
        if source < 0:
            raise ValueError(f"source device index must be >= 0, got {source!r}")
        return "device", source
    s = str(source).strip()
    if not s:
        raise ValueError(f"source must not be empty, got {source!r}")
    if s.isdigit():
        return "device", int(s)
    if s.startswith("/dev/video") and s[len("/dev/video") :].isdigit():
        return "device", int(s[len("/dev/video") :])
    if s.lower().startswith(_URL_SCHEMES):
        return "stream", s
    return "file", s


def _default_factory(source: int | str, api: int, params: list[int]) -> Any:
    return cv2.VideoCapture(source, api, params)


class _Capture:
    """One ``cv2.VideoCapture`` and the lock that keeps read and release apart."""

    def __init__(self, cap: Any) -> None:
        self.cap = cap
        self.lock = threading.Lock()
        self.abandoned = False

    def read(self) -> tuple[bool, Any]:
        with self.lock:
            if self.abandoned:
                return False, None
            ok, img = self.cap.read()
            if self.abandoned:  # timed out meanwhile: the async side moved on
                self.cap.release()
            return bool(ok), img

    def release(self) -> None:
        self.abandoned = True
        if self.lock.acquire(blocking=False):
            try:
                self.cap.release()
            finally:
                self.lock.release()
        # else: a read is in flight; ``read`` releases the capture when it returns.


class OpenCVCamera:
    """Frames from ``cv2.VideoCapture``: a V4L2 device, a video file or a stream URL.

    Parameters
    ----------
    source : int or str or Path
        Device index (``0``), ``"/dev/video0"``, a video file path, or a stream URL.
    width, height : int or None
        Frame size to request from a device (``CAP_PROP_FRAME_WIDTH/HEIGHT``); None keeps
        the driver's default.  Ignored by files and streams.
    fps : float or None
        Rate to request from a device; for every kind, ``grab()`` is also paced to at most
        this rate.  None: as fast as frames come.
    loop : bool
        Video files only: rewind at the end instead of raising :class:`StreamEnded`.
    reconnect_attempts : int
        Reconnection attempts per outage of a live source (0 disables reconnecting).
    backoff_initial_s, backoff_max_s : float
        First wait between attempts and its cap; the wait doubles per attempt.
    read_timeout_s, open_timeout_s : float
        Time limits for one read and one open.  They are handed to OpenCV
        (``CAP_PROP_READ_TIMEOUT_MSEC``/``CAP_PROP_OPEN_TIMEOUT_MSEC``) and enforced around the
        worker thread as well.
    api_preference : int
        ``cv2.CAP_*`` backend; default ``CAP_V4L2`` for devices on Linux, ``CAP_FFMPEG`` for
        files and streams.
    capture_factory : callable or None
        ``(source, api, params) -> VideoCapture``-like object; for tests.  Default
        ``cv2.VideoCapture``.
    step : bool
        Video files only, a recorded cell: ``grab()`` returns the current frame again
        (with a new time stamp) until :meth:`advance` moves to the next one, so each look
        of the cell takes the next frame of the recording (as
        :class:`vision.sources.ImageFolderCamera` does with ``step=True``); frames carry
        ``meta["replay_step"]``.
    """

    name = "opencv"

    def __init__(
        self,
        source: int | str | Path,
        *,
        width: int | None = None,
        height: int | None = None,
        fps: float | None = None,
        loop: bool = False,
        reconnect_attempts: int = 5,
        backoff_initial_s: float = 0.5,
        backoff_max_s: float = 10.0,
        read_timeout_s: float = 5.0,
        open_timeout_s: float = 10.0,
        api_preference: int | None = None,
        capture_factory: CaptureFactory | None = None,
        step: bool = False,
    ) -> None:
        self.kind, self._target = classify_source(source)
        if not isinstance(step, bool) or (step and self.kind != "file"):
            raise ValueError(
                f"step must be a bool and needs a video file, got {step!r} for {source!r}"
            )
        self.step = step
        self._steps = 0
        self._held: tuple[int, NDArray[np.uint8]] | None = None  # (step, BGR pixels)
        for pname, val in (("width", width), ("height", height)):
            if val is not None and (not isinstance(val, int) or val <= 0):
                raise ValueError(f"{pname} must be a positive int or None, got {val!r}")
        if fps is not None and not fps > 0:
            raise ValueError(f"fps must be positive or None, got {fps!r}")
        if reconnect_attempts < 0:
            raise ValueError(f"reconnect_attempts must be >= 0, got {reconnect_attempts!r}")
        for pname, seconds in (
            ("backoff_initial_s", backoff_initial_s),
            ("backoff_max_s", backoff_max_s),
            ("read_timeout_s", read_timeout_s),
            ("open_timeout_s", open_timeout_s),
        ):
            if not seconds > 0:
                raise ValueError(f"{pname} must be positive, got {seconds!r}")
        self.source = source
        self.width, self.height, self.fps, self.loop = width, height, fps, loop
        self.reconnect_attempts = reconnect_attempts
        self.backoff_initial_s, self.backoff_max_s = backoff_initial_s, backoff_max_s
        self.read_timeout_s, self.open_timeout_s = read_timeout_s, open_timeout_s
        if api_preference is None:
            use_v4l2 = self.kind == "device" and sys.platform.startswith("linux")
            api_preference = cv2.CAP_V4L2 if use_v4l2 else cv2.CAP_FFMPEG
        self.api_preference = api_preference
        self._factory: CaptureFactory = capture_factory or _default_factory
        self._cap: _Capture | None = None
        self._lock = asyncio.Lock()
        self._count = 0  # frames returned
        self._file_pos = 0  # next frame index of a video file (to resume after a reconnect)
        self._last_grab = 0.0
        self.reconnects = 0  # successful reconnections so far

    # -- description ---------------------------------------------------------------------
    def describe(self) -> str:
        """The source in words, for messages: ``V4L2 device 0 (/dev/video0)``, ``video file 'x'``."""
        if self.kind == "device":
            return f"V4L2 device {self._target} (/dev/video{self._target})"
        return f"{'video file' if self.kind == 'file' else 'stream'} {str(self._target)!r}"

    @property
    def recorded(self) -> bool:
        """Whether the source is a recording (a video file), not a live camera."""
        return self.kind == "file"

    @property
    def replay_step(self) -> int:
        """Step mode: the step number of the image the next look takes (0 first)."""
        return self._steps

    def advance(self) -> int:
        """Step mode: move on to the next frame of the file; returns the step number its
        frames carry in ``meta["replay_step"]``."""
        if not self.step:
            raise CameraError(f"advance() needs step mode ({self.describe()})")
        self._steps += 1
        return self._steps

    @property
    def is_open(self) -> bool:
        """Whether a capture is held now."""
        return self._cap is not None

    # -- blocking helpers (run in a worker thread) ---------------------------------------
    def _params(self) -> list[int]:
        return [
            cv2.CAP_PROP_OPEN_TIMEOUT_MSEC,
            round(self.open_timeout_s * 1000),
            cv2.CAP_PROP_READ_TIMEOUT_MSEC,
            round(self.read_timeout_s * 1000),
        ]

    def _open_blocking(self) -> _Capture:
        if self._factory is _default_factory:
            if self.kind == "device" and sys.platform.startswith("linux"):
                dev = Path(f"/dev/video{self._target}")
                if not dev.exists():
                    raise CameraError(f"cannot open {self.describe()}: {dev} does not exist")
            if self.kind == "file" and not Path(str(self._target)).is_file():
                raise CameraError(f"cannot open {self.describe()}: no such file")
        cap = self._factory(self._target, self.api_preference, self._params())
        if not cap.isOpened():
            cap.release()
            raise CameraError(
                f"cannot open {self.describe()}: cv2.VideoCapture refused it "
                f"(backend {self.api_preference}); check the device, path or URL"
            )
        if self.kind == "device":
            for prop, val in (
                (cv2.CAP_PROP_FRAME_WIDTH, self.width),
                (cv2.CAP_PROP_FRAME_HEIGHT, self.height),
                (cv2.CAP_PROP_FPS, self.fps),
            ):
                if val is not None:
                    cap.set(prop, float(val))
        if self.kind == "file" and self._file_pos:
            cap.set(cv2.CAP_PROP_POS_FRAMES, float(self._file_pos))
        return _Capture(cap)

    # -- lifecycle -----------------------------------------------------------------------
    async def open(self) -> None:
        """Open the source once; raises :class:`CameraError` naming it when that fails."""
        async with self._lock:
            if self._cap is None:
                self._cap = await self._run(self._open_blocking, self.open_timeout_s, "open")

    async def close(self) -> None:
        """Release the capture; idempotent."""
        async with self._lock:
            await self._drop()

    async def __aenter__(self) -> OpenCVCamera:
        await self.open()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    async def _drop(self) -> None:
        cap, self._cap = self._cap, None
        if cap is not None:
            await asyncio.to_thread(cap.release)

    async def _run(self, fn: Callable[[], Any], timeout_s: float, what: str) -> Any:
        try:
            async with asyncio.timeout(timeout_s):
                return await asyncio.to_thread(fn)
        except TimeoutError:
            raise CameraError(
                f"{what} of {self.describe()} timed out after {timeout_s} s"
            ) from None

    # -- frames --------------------------------------------------------------------------
    async def grab(self) -> Frame:
        """Return the next frame (RGB), reconnecting live sources as documented above."""
        async with self._lock:
            if self._cap is None:
                raise CameraError(f"{self.describe()} is not open")
            if self.fps is not None:
                wait = self._last_grab + 1.0 / self.fps - time.monotonic()
                if wait > 0:
                    await asyncio.sleep(wait)
            meta: dict[str, Any] = {"source": self.describe()}
            if self.step:
                held = self._held
                reads = 1 if held is None else self._steps - held[0]
                img = held[1] if held is not None else None
                for _ in range(reads):
                    img = await self._next_image()
                assert img is not None
                self._held = (self._steps, img)
                meta["replay_step"] = self._steps
            else:
                img = await self._next_image()
            meta["reconnects"] = self.reconnects
            self._last_grab = time.monotonic()
            frame = Frame(
                rgb=_rgb_from_cv(img), stamp_s=self._last_grab, index=self._count, meta=meta
            )
            self._count += 1
            return frame

    async def _next_image(self) -> NDArray[np.uint8]:
        """The next image of the source (lock held): rewound or reconnected as documented."""
        img = await self._read()
        if img is None and self.kind == "file" and Path(str(self._target)).is_file():
            img = await self._end_of_file()
        if img is None:
            img = await self._reconnect()
        if self.kind == "file":
            self._file_pos += 1
        return img

    async def _read(self) -> NDArray[np.uint8] | None:
        cap = self._cap
        if cap is None:
            return None
        try:
            async with asyncio.timeout(self.read_timeout_s):
                ok, img = await asyncio.to_thread(cap.read)
        except TimeoutError:
            log.warning("read of %s timed out after %s s", self.describe(), self.read_timeout_s)
            ok, img = False, None
        if ok and img is not None and img.size:
            return img
        return None

    async def _end_of_file(self) -> NDArray[np.uint8] | None:
        if not self.loop:
            raise StreamEnded(f"{self.describe()} ended after {self._file_pos} frame(s)")
        await self._drop()
        self._file_pos = 0
        self._cap = await self._run(self._open_blocking, self.open_timeout_s, "reopen")
        img = await self._read()
        if img is None:
            raise CameraError(f"{self.describe()} yields no frames after rewinding")
        return img

    async def _reconnect(self) -> NDArray[np.uint8]:
        await self._drop()
        if self.reconnect_attempts == 0:
            raise CameraError(f"read from {self.describe()} failed (reconnecting disabled)")
        log.warning("%s lost; reconnecting (%d attempts)", self.describe(), self.reconnect_attempts)
        t0 = time.monotonic()
        last = "read failed"
        delay = self.backoff_initial_s
        for attempt in range(1, self.reconnect_attempts + 1):
            await asyncio.sleep(delay * random.uniform(0.8, 1.2))
            delay = min(2.0 * delay, self.backoff_max_s)
            try:
                self._cap = await self._run(self._open_blocking, self.open_timeout_s, "reopen")
            except CameraError as exc:
                last = exc.detail
                continue
            img = await self._read()
            if img is not None:
                self.reconnects += 1
                log.info("%s back after %d attempt(s)", self.describe(), attempt)
                return img
            last = "opened but the first read failed"
            await self._drop()
        raise CameraError(
            f"{self.describe()} lost: {self.reconnect_attempts} reconnect attempt(s) over "
            f"{time.monotonic() - t0:.1f} s failed; last error: {last}"
        )


def _rgb_from_cv(img: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """OpenCV BGR / BGRA / grey -> RGB uint8 (the conversion at the OpenCV edge)."""
    if img.dtype != np.uint8:
        img = np.asarray(cv2.convertScaleAbs(img), dtype=np.uint8)
    if img.ndim == 2:
        code = cv2.COLOR_GRAY2RGB
    elif img.shape[2] == 4:
        code = cv2.COLOR_BGRA2RGB
    else:
        code = cv2.COLOR_BGR2RGB
    return np.asarray(cv2.cvtColor(img, code), dtype=np.uint8)
