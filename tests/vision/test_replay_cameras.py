"""Replaying a recording one image per look: the folder camera's and a video file's step
mode, and the folder's stated order (file names, or its order.txt)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from vision.errors import CameraError
from vision.opencv_camera import OpenCVCamera
from vision.sources import ORDER_FILE, ImageFolderCamera


def _image(level: int) -> np.ndarray:
    img = np.zeros((16, 20, 3), np.uint8)
    img[...] = (level, 255 - level, 7)
    return img


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    for i in range(3):
        cv2.imwrite(str(tmp_path / f"shot_{i:02d}.png"), _image(40 * (i + 1)))
    return tmp_path


async def test_step_mode_holds_each_image_until_advanced(folder):
    cam = ImageFolderCamera(folder, step=True)
    await cam.open()
    first = [await cam.grab() for _ in range(3)]
    assert {f.meta["file"] for f in first} == {"shot_00.png"}
    assert [f.meta["replay_step"] for f in first] == [0, 0, 0]
    assert first[0].stamp_s < first[1].stamp_s < first[2].stamp_s
    assert cam.replay_step == 0 and cam.advance() == 1 and cam.replay_step == 1
    f = await cam.grab()
    assert (f.meta["file"], f.meta["replay_step"]) == ("shot_01.png", 1)
    cam.advance()
    cam.advance()  # two looks before the next grab: the third image is passed, then round
    f = await cam.grab()
    assert (f.meta["file"], f.meta["replay_step"]) == ("shot_00.png", 3)


async def test_stream_mode_cannot_be_advanced(folder):
    cam = ImageFolderCamera(folder)
    await cam.open()
    with pytest.raises(CameraError, match="step mode"):
        cam.advance()


async def test_order_file_states_the_order(folder):
    (folder / ORDER_FILE).write_text("# a session\nshot_02.png\n\nshot_00.png\nshot_02.png\n")
    cam = ImageFolderCamera(folder, order="manifest")
    await cam.open()
    names = [(await cam.grab()).meta["file"] for _ in range(4)]
    assert names == ["shot_02.png", "shot_00.png", "shot_02.png", "shot_02.png"]


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        (None, "needs a file 'order.txt'"),
        ("shot_00.png\nmissing.png\n", "line 2: 'missing.png' is not an image"),
        ("../shot_00.png\n", "line 1"),
        ("order.txt\n", "line 1"),
    ],
)
async def test_bad_order_files_are_refused(folder, text, fragment):
    if text is not None:
        (folder / ORDER_FILE).write_text(text)
    with pytest.raises(CameraError, match=fragment.replace(".", r"\.").replace("(", r"\(")):
        await ImageFolderCamera(folder, order="manifest").open()


def test_bad_options_are_refused(folder):
    with pytest.raises(ValueError, match="order must be one of name, manifest"):
        ImageFolderCamera(folder, order="random")
    with pytest.raises(ValueError, match="step must be true or false"):
        ImageFolderCamera(folder, step=1)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="needs a video file"):
        OpenCVCamera(0, step=True)


async def test_video_file_steps_one_frame_per_advance(tmp_path):
    path = tmp_path / "rec.avi"
    out = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (20, 16))
    assert out.isOpened()
    for level in (30, 130, 230):
        out.write(_image(level))
    out.release()
    cam = OpenCVCamera(str(path), loop=True, step=True)
    assert cam.recorded
    async with cam:
        seen = []
        for _ in range(4):
            frames = [await cam.grab() for _ in range(2)]
            assert frames[0].meta["replay_step"] == frames[1].meta["replay_step"] == cam.replay_step
            assert np.array_equal(frames[0].rgb, frames[1].rgb)
            seen.append(int(frames[0].rgb[..., 2].mean()))  # BGR level -> RGB blue channel
            cam.advance()
    assert [round(v, -1) for v in seen] == [30, 130, 230, 30]  # and round again
