"""Limits on uploaded images, shared by every route that accepts them.

An upload is read with a byte cap (:func:`read_capped`: never more than ``limit + 1`` bytes
are held), and its width and height are read from the file header (:func:`header_size`)
and checked against a pixel budget before anything is decoded, so a small file that
declares a huge image (an "image bomb", e.g. a 50000 x 50000 PNG of a few kilobytes)
is refused with 413 instead of being decompressed.
"""

from __future__ import annotations

import struct

from fastapi import UploadFile

from backend.recognition import images as im
from vision.errors import InvalidInput

__all__ = ["check_image_size", "header_size", "read_capped"]


async def read_capped(f: UploadFile, limit: int) -> bytes:
    """The bytes of upload ``f``; :class:`~backend.recognition.images.ImageTooLarge` (413)
    if it has more than ``limit`` bytes."""
    data = await f.read(limit + 1)
    if len(data) > limit:
        raise im.ImageTooLarge(
            f"{f.filename!r} has more than {limit} bytes; the limit is {limit} bytes per image"
        )
    return data


def _tiff_size(data: bytes, name: str) -> tuple[int, int]:
    order = "<" if data[:2] == b"II" else ">"
    try:
        (ifd,) = struct.unpack(order + "I", data[4:8])
        (count,) = struct.unpack(order + "H", data[ifd : ifd + 2])
        found: dict[int, int] = {}
        for k in range(min(count, 512)):
            entry = data[ifd + 2 + 12 * k : ifd + 14 + 12 * k]
            tag, typ, _n = struct.unpack(order + "HHI", entry[:8])
            if tag in (256, 257):
                value = entry[8:10] if typ == 3 else entry[8:12]
                found[tag] = struct.unpack(order + ("H" if typ == 3 else "I"), value)[0]
    except struct.error:
        raise InvalidInput(f"{name!r}: the TIFF header is cut short") from None
    if 256 not in found or 257 not in found:
        raise InvalidInput(f"{name!r}: the TIFF header has no image size")
    return found[256], found[257]


def header_size(data: bytes, *, name: str = "image") -> tuple[int, int]:
    """(width, height) in pixels of a PNG, JPEG, BMP or TIFF file, from its header only.

    Raises
    ------
    InvalidInput
        Not one of these formats, or the header is cut short.
    """
    if data.startswith(b"BM"):
        if len(data) < 26:
            raise InvalidInput(f"{name!r}: the BMP header is cut short")
        (dib,) = struct.unpack("<I", data[14:18])
        if dib == 12:
            w, h = struct.unpack("<HH", data[18:22])
        else:
            w, h = struct.unpack("<ii", data[18:26])
        return abs(int(w)), abs(int(h))
    if data[:4] in (b"II*\x00", b"MM\x00*"):
        return _tiff_size(data, name)
    head = im.read_header(data, name=name)  # PNG or JPEG
    return head.width, head.height


def check_image_size(
    data: bytes,
    *,
    name: str = "image",
    max_bytes: int = im.MAX_IMAGE_BYTES,
    max_pixels: int = im.MAX_IMAGE_PIXELS,
    max_side: int = im.MAX_IMAGE_SIDE,
) -> tuple[int, int]:
    """Refuse ``data`` (413) if it has too many bytes, or its header declares too many
    pixels or too long a side; returns (width, height).  Nothing is decoded."""
    if len(data) > max_bytes:
        raise im.ImageTooLarge(f"{name!r} has {len(data)} bytes; the limit is {max_bytes} bytes")
    if not data:
        raise InvalidInput(f"{name!r} is empty")
    w, h = header_size(data, name=name)
    if w < 1 or h < 1:
        raise InvalidInput(f"{name!r} declares {w} x {h} px")
    if max(w, h) > max_side or w * h > max_pixels:
        raise im.ImageTooLarge(
            f"{name!r} declares {w} x {h} = {w * h} px; the limit is {max_pixels} px and "
            f"{max_side} px per side"
        )
    return w, h
