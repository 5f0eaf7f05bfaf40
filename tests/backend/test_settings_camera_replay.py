"""Settings of a camera without the simulator: replay mode, replay order, transfer curve."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from backend.hardware import make_camera
from backend.settings import Settings


def test_defaults_keep_a_streaming_camera_and_choose_the_curve_by_kind():
    s = Settings()
    assert (s.camera_replay, s.camera_order, s.camera_transfer) == ("stream", "name", "auto")
    assert s.resolved_camera_transfer() == ("linear", "srgb")  # the simulated camera
    for kind in ("folder", "opencv"):
        assert Settings(camera=kind).resolved_camera_transfer() == ("linear", "linear")
    for curve in ("linear", "srgb"):
        assert Settings(camera_transfer=curve).resolved_camera_transfer() == (curve, curve)


def test_read_from_the_environment(monkeypatch):
    monkeypatch.setenv("VISIONCELL_CAMERA", "folder")
    monkeypatch.setenv("VISIONCELL_CAMERA_REPLAY", "look")
    monkeypatch.setenv("VISIONCELL_CAMERA_ORDER", "manifest")
    monkeypatch.setenv("VISIONCELL_CAMERA_TRANSFER", "linear")
    s = Settings()
    assert (s.camera_replay, s.camera_order, s.camera_transfer) == ("look", "manifest", "linear")


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("camera_replay", "loop"),
        ("camera_replay", ""),
        ("camera_order", "random"),
        ("camera_order", 1),
        ("camera_transfer", "gamma"),
        ("camera_transfer", None),
    ],
)
def test_bad_values_name_the_setting(field, value):
    with pytest.raises(ValidationError) as e:
        Settings(camera="folder", **{field: value})
    assert field in str(e.value)


def test_inconsistent_combinations_are_refused():
    with pytest.raises(ValidationError, match="replays a recording"):
        Settings(camera="sim", camera_replay="look")
    with pytest.raises(ValidationError, match="folder camera's images"):
        Settings(camera="opencv", camera_order="manifest")


def test_a_live_device_cannot_replay_one_image_per_look(tmp_path):
    s = Settings(camera="opencv", camera_device="0", camera_replay="look")
    with pytest.raises(ValueError, match="needs a video file"):
        make_camera(s)
    cam = make_camera(Settings(camera="folder", camera_folder=tmp_path, camera_replay="look",
                               camera_order="manifest"))  # fmt: skip
    assert cam.step is True and cam.order == "manifest" and cam.recorded is True
