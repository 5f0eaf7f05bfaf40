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

__all__ = ["IMAGE_SUFFIXES", "Camera", "Frame", "ImageFolderCamera", "read_rgb"]

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".ppm", ".pgm")


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


class ImageFolderCamera:
    """Replays the images of a folder (sorted by name), for demos and tests.

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
    """

    name = "folder"

    def __init__(
        self,
        folder: str | Path,
        *,
        loop: bool = True,
        fps: float | None = None,
        pattern: str = "*",
    ) -> None:
        if fps is not None and not fps > 0:
            raise ValueError(f"fps must be positive or None, got {fps!r}")
        self.folder = Path(folder)
        self.loop = loop
        self.fps = fps
        self.pattern = pattern
        self._files: Sequence[Path] = ()
        self._next = 0
        self._count = 0
        self._last_grab = 0.0

    @property
    def files(self) -> Sequence[Path]:
        """The image files this source replays, in order."""
        return self._files

    async def open(self) -> None:
        if not self.folder.is_dir():
            raise CameraError(f"image folder {str(self.folder)!r} does not exist")
        files = sorted(
            p for p in self.folder.glob(self.pattern) if p.suffix.lower() in IMAGE_SUFFIXES
        )
        if not files:
            raise CameraError(
                f"image folder {str(self.folder)!r} holds no images matching {self.pattern!r}"
            )
        self._files = files
        self._next = 0

    async def close(self) -> None:
        self._files = ()

    async def grab(self) -> Frame:
        if not self._files:
            raise CameraError("image folder camera is not open")
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
