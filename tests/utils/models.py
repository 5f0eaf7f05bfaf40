"""Factories for the object-model tests: textured images with many features, crafted files."""

from __future__ import annotations

import struct
import zlib

import cv2
import numpy as np


def textured_rgb(seed: int, *, size: tuple[int, int] = (240, 320)) -> np.ndarray:
    """An RGB uint8 (H, W, 3) image of random shapes on grey: hundreds of SIFT features."""
    rng = np.random.default_rng(seed)
    h, w = size
    img = np.full((h, w, 3), 128, np.uint8)
    for _ in range(60):
        colour = tuple(int(c) for c in rng.integers(0, 256, 3))
        x, y = int(rng.integers(0, w)), int(rng.integers(0, h))
        if rng.random() < 0.5:
            cv2.circle(img, (x, y), int(rng.integers(4, 25)), colour, -1)
        else:
            cv2.rectangle(
                img,
                (x, y),
                (x + int(rng.integers(5, 40)), y + int(rng.integers(5, 40))),
                colour,
                -1,
            )
    return img


def png_bytes(rgb: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".png", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    assert ok
    return buf.tobytes()


def jpeg_bytes(rgb: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    assert ok
    return buf.tobytes()


def png_bomb(width: int = 60_000, height: int = 60_000) -> bytes:
    """A tiny, well-formed PNG header announcing a ``width`` x ``height`` image (an image bomb:
    its IDAT would inflate to gigabytes; the server must refuse it from the header alone)."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (
            struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
        )

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    idat = zlib.compress(b"\x00" * 65536, 9)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", idat) + chunk(b"IEND", b"")
