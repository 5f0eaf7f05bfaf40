"""ImageFolderCamera: replay order, looping, pacing, errors."""

from pathlib import Path

import cv2
import numpy as np
import pytest

from vision.errors import CameraError, StreamEnded
from vision.sources import Camera, ImageFolderCamera, read_rgb


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    # Written out of order, with a non-image file and a grey image among them.
    for i in (2, 0, 1):
        img = np.zeros((8, 10, 3), np.uint8)
        img[..., 2] = 200  # red in BGR
        img[..., 1] = 50 * i
        cv2.imwrite(str(tmp_path / f"img_{i:02d}.png"), img)
    cv2.imwrite(str(tmp_path / "img_03.png"), np.full((8, 10), 77, np.uint8))
    (tmp_path / "notes.txt").write_text("not an image")
    return tmp_path


async def test_replays_in_name_order_as_rgb(folder):
    cam = ImageFolderCamera(folder, loop=False)
    assert isinstance(cam, Camera)
    await cam.open()
    assert [p.name for p in cam.files] == [f"img_{i:02d}.png" for i in range(4)]
    frames = [await cam.grab() for _ in range(4)]
    assert [f.meta["file"] for f in frames] == [f"img_{i:02d}.png" for i in range(4)]
    assert [f.index for f in frames] == [0, 1, 2, 3]
    for i, f in enumerate(frames[:3]):
        assert f.rgb[0, 0].tolist() == [200, 50 * i, 0]  # RGB order
    assert frames[3].rgb.shape == (8, 10, 3) and frames[3].rgb[0, 0].tolist() == [77] * 3
    with pytest.raises(StreamEnded, match="is exhausted"):
        await cam.grab()


async def test_loops_and_keeps_counting(folder):
    cam = ImageFolderCamera(folder, pattern="img_0[0-2].png")
    await cam.open()
    names = [(await cam.grab()).meta["file"] for _ in range(7)]
    assert names == ["img_00.png", "img_01.png", "img_02.png"] * 2 + ["img_00.png"]


async def test_fps_paces_grabs(folder):
    cam = ImageFolderCamera(folder, fps=50.0)
    await cam.open()
    stamps = [(await cam.grab()).stamp_s for _ in range(5)]
    assert min(np.diff(stamps)) >= 1 / 50.0 - 2e-3


async def test_empty_folder_is_an_error(tmp_path):
    (tmp_path / "readme.txt").write_text("x")
    with pytest.raises(CameraError, match="holds no images matching '\\*'"):
        await ImageFolderCamera(tmp_path).open()


async def test_missing_folder_and_grab_before_open(tmp_path):
    with pytest.raises(CameraError, match="does not exist"):
        await ImageFolderCamera(tmp_path / "nope").open()
    with pytest.raises(CameraError, match="not open"):
        await ImageFolderCamera(tmp_path).grab()


def test_bad_fps_and_unreadable_file(tmp_path):
    with pytest.raises(ValueError, match="fps must be positive or None, got -1"):
        ImageFolderCamera(tmp_path, fps=-1)
    bad = tmp_path / "broken.png"
    bad.write_bytes(b"not a png")
    with pytest.raises(CameraError, match="cannot read image"):
        read_rgb(bad)
