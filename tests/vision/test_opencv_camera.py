"""OpenCVCamera on a generated video file, a missing device, and a flaky fake capture."""

import asyncio
import logging
from pathlib import Path

import cv2
import numpy as np
import pytest

from vision.errors import CameraError, StreamEnded
from vision.opencv_camera import OpenCVCamera, classify_source
from vision.sources import Camera

N_FRAMES = 6


def _frame_bgr(i: int) -> np.ndarray:
    # Red in RGB terms (high in BGR's last channel), and a brightness that numbers the frame.
    img = np.zeros((48, 64, 3), np.uint8)
    img[:, :, 2] = 220
    img[:, :, 1] = 30 * i
    return img


@pytest.fixture
def video(tmp_path: Path) -> Path:
    path = tmp_path / "clip.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (64, 48))
    assert writer.isOpened()
    for i in range(N_FRAMES):
        writer.write(_frame_bgr(i))
    writer.release()
    return path


def _frame_number(rgb: np.ndarray) -> int:
    return round(float(rgb[..., 1].mean()) / 30.0)


async def test_video_file_frames_are_rgb_in_order_then_stream_ends(video):
    cam = OpenCVCamera(video)
    assert isinstance(cam, Camera) and cam.kind == "file"
    await cam.open()
    got = []
    for _ in range(N_FRAMES):
        f = await cam.grab()
        assert f.rgb.shape == (48, 64, 3) and f.rgb.dtype == np.uint8
        # RGB order: red dominates channel 0 (OpenCV would give it in channel 2).
        assert f.rgb[..., 0].mean() > 200 and f.rgb[..., 2].mean() < 20
        got.append((_frame_number(f.rgb), f.index))
    assert got == [(i, i) for i in range(N_FRAMES)]
    with pytest.raises(StreamEnded, match=r"video file .*clip\.avi' ended after 6 frame"):
        await cam.grab()
    # It stays ended (no silent rewind); StreamEnded is a CameraError.
    with pytest.raises(CameraError):
        await cam.grab()
    await cam.close()
    await cam.close()  # idempotent


async def test_video_file_loops_when_asked(video):
    async with OpenCVCamera(video, loop=True) as cam:
        numbers = [_frame_number((await cam.grab()).rgb) for _ in range(2 * N_FRAMES + 2)]
    assert numbers == [*range(N_FRAMES), *range(N_FRAMES), 0, 1]


async def test_fps_paces_grabs(video):
    async with OpenCVCamera(video, fps=40.0) as cam:
        stamps = [(await cam.grab()).stamp_s for _ in range(4)]
    assert min(np.diff(stamps)) >= 1 / 40.0 - 2e-3


async def test_missing_device_gives_clear_error():
    cam = OpenCVCamera(97)
    assert cam.kind == "device"
    with pytest.raises(CameraError, match=r"cannot open V4L2 device 97 \(/dev/video97\)"):
        await cam.open()
    assert not cam.is_open


async def test_missing_file_gives_clear_error(tmp_path):
    with pytest.raises(CameraError, match=r"cannot open video file .*nope\.avi'.*no such file"):
        await OpenCVCamera(tmp_path / "nope.avi").open()


async def test_grab_before_open_is_an_error(video):
    with pytest.raises(CameraError, match="is not open"):
        await OpenCVCamera(video).grab()


@pytest.mark.parametrize(
    ("source", "kind", "target"),
    [
        (0, "device", 0),
        ("2", "device", 2),
        ("/dev/video3", "device", 3),
        ("rtsp://cam.local/stream", "stream", "rtsp://cam.local/stream"),
        ("HTTP://x/y.mjpg", "stream", "HTTP://x/y.mjpg"),
        ("clips/a.mp4", "file", "clips/a.mp4"),
    ],
)
def test_classify_source(source, kind, target):
    assert classify_source(source) == (kind, target)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"source": -1}, "device index must be >= 0, got -1"),
        ({"source": ""}, "source must not be empty"),
        ({"source": True}, "source must be a device index"),
        ({"source": 0, "fps": 0}, "fps must be positive or None, got 0"),
        ({"source": 0, "width": -640}, "width must be a positive int or None, got -640"),
        ({"source": 0, "reconnect_attempts": -1}, "reconnect_attempts must be >= 0"),
        ({"source": 0, "read_timeout_s": 0.0}, "read_timeout_s must be positive, got 0.0"),
    ],
)
def test_bad_parameters(kwargs, match):
    with pytest.raises(ValueError, match=match):
        OpenCVCamera(**kwargs)


class FlakyCapture:
    """A fake VideoCapture: the shared ``plan`` says, per read, ok / fail / hang."""

    def __init__(self, plan: list[str]) -> None:
        self.plan = plan  # shared list of "ok" / "fail" / "hang", consumed per read
        self.released = False

    def isOpened(self) -> bool:
        return True

    def set(self, prop, val) -> bool:
        return True

    def read(self):
        step = self.plan.pop(0) if self.plan else "ok"
        if step == "hang":
            import time

            time.sleep(0.3)
            return False, None
        if step == "fail":
            return False, None
        return True, _frame_bgr(1)

    def release(self) -> None:
        self.released = True


class FlakyFactory:
    def __init__(self, plan: list[str], refuse_opens: int = 0) -> None:
        self.plan = plan
        self.refuse_opens = refuse_opens
        self.opened: list[FlakyCapture] = []

    def __call__(self, source, api, params):
        if self.refuse_opens > 0:
            self.refuse_opens -= 1
            cap = FlakyCapture(self.plan)
            cap.isOpened = lambda: False  # type: ignore[method-assign]
            return cap
        cap = FlakyCapture(self.plan)
        self.opened.append(cap)
        return cap


def _flaky_camera(factory, **kw) -> OpenCVCamera:
    return OpenCVCamera(
        0, capture_factory=factory, backoff_initial_s=0.01, backoff_max_s=0.02, **kw
    )


async def test_device_that_disappears_is_reconnected_with_backoff(caplog):
    factory = FlakyFactory(["ok", "fail"], refuse_opens=0)
    cam = _flaky_camera(factory)
    await cam.open()
    assert (await cam.grab()).meta["reconnects"] == 0
    # The device vanishes: the read fails and the first two reopen attempts are refused.
    factory.refuse_opens = 2
    with caplog.at_level(logging.INFO, logger="vision.opencv_camera"):
        f = await cam.grab()
    assert f.meta["reconnects"] == 1 and cam.reconnects == 1 and f.index == 1
    assert f.rgb[..., 0].mean() > 200  # still converted to RGB
    assert factory.opened[0].released  # the dead capture was released
    assert "lost; reconnecting" in caplog.text and "back after 3 attempt(s)" in caplog.text
    await cam.close()


async def test_reconnect_gives_up_with_a_clear_error_then_retries_on_next_grab():
    factory = FlakyFactory(["fail"])
    cam = _flaky_camera(factory, reconnect_attempts=3)
    await cam.open()
    factory.refuse_opens = 3
    with pytest.raises(CameraError, match=r"V4L2 device 0 .* lost: 3 reconnect attempt\(s\)"):
        await cam.grab()
    assert not cam.is_open
    with pytest.raises(CameraError, match="is not open"):
        await cam.grab()
    await cam.open()  # the device is back: the caller reopens
    assert (await cam.grab()).rgb.shape == (48, 64, 3)


async def test_a_hanging_read_times_out_and_reconnects():
    factory = FlakyFactory(["hang"])
    cam = _flaky_camera(factory, read_timeout_s=0.05)
    await cam.open()
    f = await cam.grab()
    assert cam.reconnects == 1 and f.rgb.shape == (48, 64, 3)
    await asyncio.sleep(0.35)  # the abandoned read returns and releases its capture
    assert factory.opened[0].released
    await cam.close()


async def test_reconnect_disabled_fails_at_once():
    cam = _flaky_camera(FlakyFactory(["fail"]), reconnect_attempts=0)
    await cam.open()
    with pytest.raises(CameraError, match="reconnecting disabled"):
        await cam.grab()
