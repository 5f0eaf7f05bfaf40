"""Image sources behind one ``Camera`` protocol.

Every source returns :class:`Frame` objects from an async ``grab()``.  The backend's
acquisition task keeps only the newest frame (a latest-frame slot, never a growing queue).
The simulator adds ``SimCamera`` in ``robot.sim``; ``OpenCVCamera`` lives in
``vision.opencv_camera``.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from vision.errors import CameraError, StreamEnded

__all__ = [
    "IMAGE_SUFFIXES",
    "ORDER_FILE",
    "REPLAY_ORDERS",
    "Camera",
    "Frame",
    "ImageFolderCamera",
    "read_order",
    "read_rgb",
]

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".ppm", ".pgm")
#: How a folder camera orders its images: by file name (sorted as strings, so number them
#: with leading zeros), or as listed in the folder's :data:`ORDER_FILE`.
REPLAY_ORDERS = ("name", "manifest")
#: The replay order of a folder (``order="manifest"``): one file name per line; blank lines
#: and lines starting with ``#`` are skipped; a name may appear more than once.
ORDER_FILE = "order.txt"
#: Most images one replay order lists.
MAX_ORDER_ENTRIES = 100_000


@dataclass(frozen=True)
class Frame:
    """One image from a source.

    Attributes
    ----------
    rgb : ndarray of shape (H, W, 3), uint8
        Pixels in RGB order.
    stamp_s : float
        ``time.monotonic()`` at exposure (or at read for sources that do not know better).
    index : int
        Running number of the frame from this source.
    robot_state : object or None
        The arm's state at exposure when the source knows it (the simulator does); its type
        belongs to ``robot`` and is opaque here.
    meta : dict
        Source-specific facts (file name, device, exposure).
    """

    rgb: NDArray[np.uint8]
    stamp_s: float = field(default_factory=time.monotonic)
    index: int = 0
    robot_state: Any = None
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def height(self) -> int:
        """Image height, pixels."""
        return int(self.rgb.shape[0])

    @property
    def width(self) -> int:
        """Image width, pixels."""
        return int(self.rgb.shape[1])


@runtime_checkable
class Camera(Protocol):
    """An image source."""

    name: str

    async def open(self) -> None:
        """Acquire the device or resource."""

    async def close(self) -> None:
        """Release it; idempotent."""

    async def grab(self) -> Frame:
        """Return the next frame; raises :class:`~vision.errors.CameraError` on failure."""


def read_rgb(path: str | Path) -> NDArray[np.uint8]:
    """Read an image file as RGB uint8 (grey images are replicated to three channels)."""
    import cv2

    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if img is None:
        raise CameraError(f"cannot read image {str(path)!r}")
    return np.asarray(cv2.cvtColor(img, cv2.COLOR_BGR2RGB), dtype=np.uint8)


def read_order(folder: Path, *, pattern: str = "*") -> list[Path]:
    """The images of ``folder`` in the order its :data:`ORDER_FILE` lists them.

    Raises :class:`~vision.errors.CameraError` naming the file and line when the order file
    is missing, too long, or names a file that is not an image directly in ``folder``.
    """
    path = folder / ORDER_FILE
    if not path.is_file():
        raise CameraError(f"replay order 'manifest' needs a file {ORDER_FILE!r} in {str(folder)!r}")
    if path.stat().st_size > 64 * MAX_ORDER_ENTRIES:
        raise CameraError(f"{str(path)!r} is too large for a replay order")
    out: list[Path] = []
    for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
        name = line.strip()
        if not name or name.startswith("#"):
            continue
        p = folder / name
        if Path(name).name != name or p.suffix.lower() not in IMAGE_SUFFIXES or not p.is_file():
            raise CameraError(f"{str(path)!r} line {n}: {name!r} is not an image in the folder")
        if not p.match(pattern):
            continue
        out.append(p)
        if len(out) > MAX_ORDER_ENTRIES:
            raise CameraError(f"{str(path)!r} lists more than {MAX_ORDER_ENTRIES} images")
    return out


class ImageFolderCamera:
    """Replays the images of a folder, for recorded cells, demos and tests.

    Two ways to replay:

    * ``step=False`` (a stream): every ``grab()`` returns the next image, so the images pass
      at the acquisition rate whoever looks;
    * ``step=True`` (a recorded cell): ``grab()`` returns the current image again (with a
      new time stamp) until :meth:`advance` moves to the next, which the cell does once per
      ``look``: each look of an inspection takes the next image in the stated order, so a
      session of top and side images recorded from a real cell replays to the same views.
      Its frames carry ``meta["replay_step"]``, the count of advances, so a reader can tell
      a frame of the image it asked for from an older one.

    Parameters
    ----------
    folder : path
        Directory holding images with one of :data:`IMAGE_SUFFIXES`.
    loop : bool
        Start again after the last image (else ``grab()`` raises
        :class:`~vision.errors.StreamEnded`, a ``CameraError``).
    fps : float or None
        Pace ``grab()`` to this rate; None returns frames as fast as they are read.
    pattern : str
        Glob filter applied to the file names.
    order : {"name", "manifest"}
        File names sorted as strings, or the folder's :data:`ORDER_FILE`.
    step : bool
        Each image until :meth:`advance` (a recorded cell) instead of a stream.
    """

    name = "folder"
    #: The images were recorded: the camera cannot look at what the arm points it at.
    recorded = True

    def __init__(
        self,
        folder: str | Path,
        *,
        loop: bool = True,
        fps: float | None = None,
        pattern: str = "*",
        order: str = "name",
        step: bool = False,
    ) -> None:
        if fps is not None and not fps > 0:
            raise ValueError(f"fps must be positive or None, got {fps!r}")
        if order not in REPLAY_ORDERS:
            raise ValueError(f"order must be one of {', '.join(REPLAY_ORDERS)}, got {order!r}")
        if not isinstance(step, bool):
            raise ValueError(f"step must be true or false, got {step!r}")
        self.folder = Path(folder)
        self.loop = loop
        self.fps = fps
        self.pattern = pattern
        self.order = order
        self.step = step
        self._files: Sequence[Path] = ()
        self._next = 0
        self._count = 0
        self._last_grab = 0.0
        self._steps = 0  # advances so far (step mode)
        self._held: tuple[int, Path, NDArray[np.uint8]] | None = None  # (step, file, pixels)

    @property
    def files(self) -> Sequence[Path]:
        """The image files this source replays, in order."""
        return self._files

    async def open(self) -> None:
        if not self.folder.is_dir():
            raise CameraError(f"image folder {str(self.folder)!r} does not exist")
        if self.order == "manifest":
            files = await asyncio.to_thread(read_order, self.folder, pattern=self.pattern)
        else:
            files = sorted(
                p for p in self.folder.glob(self.pattern) if p.suffix.lower() in IMAGE_SUFFIXES
            )
        if not files:
            raise CameraError(
                f"image folder {str(self.folder)!r} holds no images matching {self.pattern!r}"
            )
        self._files = files
        if not self.step:
            self._next = 0
        # A recorded cell re-opened after a camera fault goes on where it was.
        self._next = min(self._next, len(files))

    async def close(self) -> None:
        self._files = ()
        self._held = None

    @property
    def replay_step(self) -> int:
        """Step mode: the step number of the image the next look takes (0 first)."""
        return self._steps

    def advance(self) -> int:
        """Step mode: move on to the next image; returns the step number its frames carry
        in ``meta["replay_step"]``."""
        if not self.step:
            raise CameraError("advance() needs a folder camera in step mode")
        self._steps += 1
        return self._steps

    async def grab(self) -> Frame:
        if not self._files:
            raise CameraError("image folder camera is not open")
        if self.step:
            return await self._grab_step()
        if self._next >= len(self._files):
            if not self.loop:
                raise StreamEnded(f"image folder {str(self.folder)!r} is exhausted")
            self._next = 0
        if self.fps is not None:
            wait = self._last_grab + 1.0 / self.fps - time.monotonic()
            if wait > 0:
                await asyncio.sleep(wait)
        path = self._files[self._next]
        rgb = await asyncio.to_thread(read_rgb, path)
        self._last_grab = time.monotonic()
        frame = Frame(rgb=rgb, stamp_s=self._last_grab, index=self._count, meta={"file": path.name})
        self._next += 1
        self._count += 1
        return frame

    async def _grab_step(self) -> Frame:
        """The image of the current step (read once), stamped now."""
        if self._held is None or self._held[0] != self._steps:
            step = self._steps
            if self._held is not None:  # the first image is step 0; each advance the next
                self._next += step - self._held[0]
            if self._next >= len(self._files):
                if not self.loop:
                    raise StreamEnded(f"image folder {str(self.folder)!r} is exhausted")
                self._next %= len(self._files)
            path = self._files[self._next]
            self._held = (step, path, await asyncio.to_thread(read_rgb, path))
        elif self.fps is not None:
            wait = self._last_grab + 1.0 / self.fps - time.monotonic()
            if wait > 0:
                await asyncio.sleep(wait)
        step, path, rgb = self._held
        self._last_grab = time.monotonic()
        frame = Frame(rgb=rgb, stamp_s=self._last_grab, index=self._count,
                      meta={"file": path.name, "replay_step": step})  # fmt: skip
        self._count += 1
        return frame
