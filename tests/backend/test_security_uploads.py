"""Uploads are limited in bytes and in declared pixels before anything is decoded."""

from __future__ import annotations

import struct

import cv2
import numpy as np
import pytest

from backend.api import uploads
from backend.recognition.images import MAX_IMAGE_BYTES, ImageTooLarge
from tests.utils.models import png_bomb
from vision.errors import InvalidInput

BOARD = {"type": "chessboard", "cols": 9, "rows": 6, "square_mm": 30}


def _session(client, headers) -> int:
    r = client.post("/api/calibration/sessions", json={"kind": "intrinsic", "board": BOARD},
                    headers=headers["engineer"])  # fmt: skip
    assert r.status_code == 201, r.text
    return r.json()["session"]["id"]


def _bmp_bomb(w: int, h: int) -> bytes:
    dib = struct.pack("<IiiHHIIiiII", 40, w, h, 1, 24, 0, 0, 2835, 2835, 0, 0)
    return b"BM" + struct.pack("<IHHI", 14 + len(dib), 0, 0, 14 + len(dib)) + dib


def _tiff_bomb(w: int, h: int) -> bytes:
    entries = [(256, 4, 1, w), (257, 4, 1, h)]
    ifd = struct.pack("<H", len(entries))
    ifd += b"".join(struct.pack("<HHII", *e) for e in entries) + struct.pack("<I", 0)
    return b"II*\x00" + struct.pack("<I", 8) + ifd


@pytest.mark.parametrize(
    ("data", "name"),
    [(png_bomb(50_000, 50_000), "bomb.png"), (_bmp_bomb(50_000, 50_000), "bomb.bmp"),
     (_tiff_bomb(50_000, 50_000), "bomb.tif")],
)  # fmt: skip
def test_calibration_refuses_an_image_bomb_from_its_header(
    client, headers, data, name, monkeypatch
):
    import backend.api.routes.calibration as cal

    decoded = []
    real = cv2.imdecode
    monkeypatch.setattr(cal.cv2, "imdecode", lambda *a: decoded.append(1) or real(*a))
    sid = _session(client, headers)
    r = client.post(f"/api/calibration/sessions/{sid}/samples",
                    files=[("images", (name, data, "application/octet-stream"))],
                    headers=headers["engineer"])  # fmt: skip
    assert r.status_code == 413, r.text
    assert r.json()["error"] == "too_large" and "50000 x 50000" in r.json()["detail"]
    assert decoded == []  # refused before decoding


def test_calibration_refuses_too_many_bytes(client, headers):
    sid = _session(client, headers)
    data = b"\x89PNG" + b"\x00" * (MAX_IMAGE_BYTES + 10)
    r = client.post(f"/api/calibration/sessions/{sid}/samples",
                    files=[("images", ("big.png", data, "image/png"))],
                    headers=headers["engineer"])  # fmt: skip
    assert r.status_code == 413 and r.json()["error"] == "too_large"


def test_header_sizes_of_real_files():
    img = np.zeros((48, 64, 3), np.uint8)
    for ext in (".png", ".jpg", ".bmp", ".tif"):
        ok, buf = cv2.imencode(ext, img)
        assert ok
        assert uploads.header_size(buf.tobytes(), name=ext) == (64, 48), ext


def test_check_image_size_errors():
    with pytest.raises(ImageTooLarge):
        uploads.check_image_size(png_bomb(50_000, 50_000))
    with pytest.raises(InvalidInput):
        uploads.check_image_size(b"")
    with pytest.raises(InvalidInput):
        uploads.check_image_size(b"II*\x00\x08\x00")  # cut short
    with pytest.raises(InvalidInput):
        uploads.check_image_size(b"GIF89a....")
