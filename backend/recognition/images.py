"""Images of trained views: bounded decoding of uploads, PNG/JPEG encoding, thumbnails.

An upload is checked in three steps, each before any work on the next: its size in bytes,
its type and pixel dimensions read from the file header (PNG ``IHDR`` or JPEG ``SOFn``;
nothing is decoded yet, so a small file that would decode to gigabytes, an "image bomb", is
refused here), then the decode itself.  Images are RGB uint8 inside; masks are boolean.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import cast

import cv2
import numpy as np
from numpy.typing import NDArray

from vision.errors import InvalidInput

__all__ = [
    "MAX_IMAGE_BYTES",
    "MAX_IMAGE_PIXELS",
    "MAX_IMAGE_SIDE",
    "MIN_IMAGE_SIDE",
    "THUMBNAIL_PX",
    "ImageHeader",
    "ImageTooLarge",
    "UnsupportedImage",
    "check_header",
    "decode_image",
    "decode_mask",
    "encode_jpeg",
    "encode_mask_png",
    "encode_png",
    "mask_from_png",
    "read_header",
    "rgb_from_png",
    "thumbnail",
]

#: Largest accepted file, bytes (a 4000 x 3000 camera image is about 36 MB as raw RGB and
#: well under this as PNG or JPEG).
MAX_IMAGE_BYTES = 16 * 1024 * 1024
#: Largest accepted image, decoded pixels (width x height).
MAX_IMAGE_PIXELS = 12_000_000
#: Largest accepted side, pixels.
MAX_IMAGE_SIDE = 8192
#: Smallest accepted side, pixels (features need at least 16).
MIN_IMAGE_SIDE = 32
#: Longest side of a thumbnail, pixels.
THUMBNAIL_PX = 160


class ImageTooLarge(InvalidInput):
    """An uploaded image has more bytes or pixels than allowed."""

    code = "too_large"


class UnsupportedImage(InvalidInput):
    """An uploaded file is not an image of a supported type, or does not decode."""

    code = "unsupported_media_type"


_PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
# JPEG start-of-frame markers that carry the image size (not DHT C4, JPG C8, DAC CC).
_SOF = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}


@dataclass(frozen=True)
class ImageHeader:
    """What a file's header says, read without decoding it."""

    format: str
    """``"png"`` or ``"jpeg"``."""
    width: int
    """Pixels."""
    height: int
    """Pixels."""


def _jpeg_size(data: bytes) -> tuple[int, int] | None:
    i = 2
    n = len(data)
    while i + 4 <= n:
        if data[i] != 0xFF:
            return None
        marker = data[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        if marker in (0xD8, 0x01) or 0xD0 <= marker <= 0xD7:  # no length field
            i += 2
            continue
        (length,) = struct.unpack(">H", data[i + 2 : i + 4])
        if length < 2:
            return None
        if marker in _SOF:
            if i + 9 > n:
                return None
            height, width = struct.unpack(">HH", data[i + 5 : i + 9])
            return width, height
        if marker == 0xD9:  # end of image before a frame
            return None
        i += 2 + length
    return None


def read_header(data: bytes, *, name: str = "image") -> ImageHeader:
    """Type and size of a PNG or JPEG file from its header (nothing is decoded).

    Raises
    ------
    InvalidInput
        The bytes are neither PNG nor JPEG, or the header is cut short.
    """
    if data.startswith(_PNG_MAGIC):
        if len(data) < 24 or data[12:16] != b"IHDR":
            raise UnsupportedImage(f"{name!r}: the PNG header is cut short")
        width, height = struct.unpack(">II", data[16:24])
        return ImageHeader("png", int(width), int(height))
    if data.startswith(b"\xff\xd8"):
        size = _jpeg_size(data)
        if size is None:
            raise UnsupportedImage(f"{name!r}: the JPEG header has no frame size")
        return ImageHeader("jpeg", size[0], size[1])
    raise UnsupportedImage(f"{name!r} is not a PNG or JPEG image (first bytes {data[:8]!r})")


def check_header(
    data: bytes,
    *,
    name: str = "image",
    max_bytes: int = MAX_IMAGE_BYTES,
    max_pixels: int = MAX_IMAGE_PIXELS,
) -> ImageHeader:
    """Refuse a file that is too large in bytes or in pixels, before decoding it."""
    if len(data) > max_bytes:
        raise ImageTooLarge(
            f"{name!r} has {len(data)} bytes; the limit is {max_bytes} bytes per image"
        )
    if not data:
        raise InvalidInput(f"{name!r} is empty")
    head = read_header(data, name=name)
    w, h = head.width, head.height
    if max(w, h) > MAX_IMAGE_SIDE:
        raise ImageTooLarge(
            f"{name!r} is {w} x {h} px; each side must be at most {MAX_IMAGE_SIDE} px"
        )
    if min(w, h) < MIN_IMAGE_SIDE:
        raise InvalidInput(
            f"{name!r} is {w} x {h} px; each side must be within "
            f"[{MIN_IMAGE_SIDE}, {MAX_IMAGE_SIDE}] px"
        )
    if w * h > max_pixels:
        raise ImageTooLarge(
            f"{name!r} is {w} x {h} = {w * h} px; the limit is {max_pixels} px per image"
        )
    return head


def decode_image(
    data: bytes,
    *,
    name: str = "image",
    max_bytes: int = MAX_IMAGE_BYTES,
    max_pixels: int = MAX_IMAGE_PIXELS,
) -> NDArray[np.uint8]:
    """An uploaded PNG or JPEG as RGB uint8 of shape (H, W, 3), after :func:`check_header`.

    Grey images are expanded to three channels; alpha is dropped; 16-bit PNGs are refused.
    """
    head = check_header(data, name=name, max_bytes=max_bytes, max_pixels=max_pixels)
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise UnsupportedImage(f"{name!r} does not decode as a {head.format.upper()} image")
    if img.dtype != np.uint8:
        raise InvalidInput(f"{name!r} must have 8 bits per channel, got {img.dtype}")
    if img.shape[:2] != (head.height, head.width):
        raise InvalidInput(
            f"{name!r} decodes to {img.shape[1]} x {img.shape[0]} px, "
            f"its header says {head.width} x {head.height}"
        )
    if img.ndim == 2:
        return _convert_u8(img, cv2.COLOR_GRAY2RGB)
    if img.shape[2] == 4:
        return _convert_u8(img, cv2.COLOR_BGRA2RGB)
    return _convert_u8(img, cv2.COLOR_BGR2RGB)


def _convert_u8(img: np.ndarray, code: int) -> NDArray[np.uint8]:
    """``cv2.cvtColor`` of an image the caller knows is uint8 (``cv2.imdecode`` output):
    uint8 out, which the OpenCV stubs cannot express (they return any array)."""
    return cast(NDArray[np.uint8], cv2.cvtColor(img, code))


def decode_mask(data: bytes, *, shape: tuple[int, int], name: str = "mask") -> NDArray[np.bool_]:
    """A mask file (PNG or JPEG; nonzero = object) as a boolean (H, W) array of ``shape``."""
    rgb = decode_image(data, name=name)
    if rgb.shape[:2] != tuple(shape):
        raise InvalidInput(
            f"{name!r} is {rgb.shape[1]} x {rgb.shape[0]} px, its image is {shape[1]} x {shape[0]} px"
        )
    mask = rgb.max(axis=2) > 127
    if not mask.any():
        raise InvalidInput(f"{name!r} is empty: no pixel marks the object")
    return mask


def encode_png(rgb: NDArray[np.uint8]) -> bytes:
    """PNG bytes of an RGB uint8 (H, W, 3) image."""
    ok, buf = cv2.imencode(".png", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    if not ok:  # pragma: no cover - OpenCV encodes every uint8 image
        raise RuntimeError("PNG encoding failed")
    return buf.tobytes()


def encode_mask_png(mask: NDArray[np.bool_]) -> bytes:
    """PNG bytes of a boolean (H, W) mask (one channel, 255 inside)."""
    ok, buf = cv2.imencode(".png", np.where(mask, 255, 0).astype(np.uint8))
    if not ok:  # pragma: no cover
        raise RuntimeError("PNG encoding failed")
    return buf.tobytes()


def mask_from_png(data: bytes) -> NDArray[np.bool_]:
    """Inverse of :func:`encode_mask_png` (stored data, trusted)."""
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise ValueError("the stored mask does not decode as PNG")
    return img > 127


def rgb_from_png(data: bytes) -> NDArray[np.uint8]:
    """Inverse of :func:`encode_png` (stored data, trusted)."""
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    if img is None:
        raise ValueError("the stored image does not decode as PNG")
    return _convert_u8(img, cv2.COLOR_BGR2RGB)


def encode_jpeg(rgb: NDArray[np.uint8], *, quality: int = 85) -> bytes:
    """JPEG bytes of an RGB uint8 image."""
    ok, buf = cv2.imencode(
        ".jpg", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, int(quality)]
    )
    if not ok:  # pragma: no cover
        raise RuntimeError("JPEG encoding failed")
    return buf.tobytes()


def thumbnail(
    rgb: NDArray[np.uint8], mask: NDArray[np.bool_] | None = None, *, size_px: int = THUMBNAIL_PX
) -> bytes:
    """A JPEG thumbnail (longest side ``size_px``) with the mask's outline drawn in green."""
    img = rgb.copy()
    if mask is not None and mask.any():
        contours, _ = cv2.findContours(
            mask.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE
        )
        width = max(1, round(max(img.shape[:2]) / size_px))
        cv2.drawContours(img, contours, -1, (0, 220, 0), width)
    scale = size_px / max(img.shape[:2])
    if scale < 1.0:
        # uint8 in, uint8 out (the OpenCV stubs only say "array").
        img = cast(
            NDArray[np.uint8],
            cv2.resize(img, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA),
        )
    return encode_jpeg(img, quality=80)
