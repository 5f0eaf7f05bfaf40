"""The empty-belt background registered to the belt's travel (vision.segmentation.belt)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from backend.recognition.segment import SegmentationFailed, foreground_mask
from vision.camera import PinholeCamera
from vision.errors import InvalidInput
from vision.pose import plane_points
from vision.segmentation.belt import BeltBackground, BeltGeometry, build_belt_background

GEO = BeltGeometry(centre_x_m=0.8, start_y_m=-1.3, width_m=0.44, surface_z_m=0.45, loop_m=2.6)
PITCH = 2.6 / 9  # stripes evenly spaced round the loop, as the simulator's
CAM = PinholeCamera(np.array([[500.0, 0, 160], [0, 500.0, 120], [0, 0, 1]]), (0.0,) * 5)


def _T_cam() -> np.ndarray:
    """Camera 0.4 m above the belt at the station, looking straight down."""
    T = np.eye(4)
    T[:3, :3] = np.diag([1.0, -1.0, -1.0])
    T[:3, 3] = (0.8, 0.0, 0.85)
    return T


def _render(travel: float, obj_at: float | None = None) -> np.ndarray:
    """The belt (dark, light cross stripes 16 mm wide moving with the travel) under a
    light falling off across the view, the floor beside it; a box on the belt if asked."""
    h, w = 240, 320
    ys, xs = np.mgrid[0:h, 0:w]
    px = np.stack([xs.ravel(), ys.ravel()], axis=1).astype(float)
    p = plane_points(px, CAM, _T_cam(), GEO.surface_z_m).reshape(h, w, 3)
    u = np.mod(p[..., 1] - GEO.start_y_m - travel, GEO.loop_m)
    stripe = np.mod(u, PITCH) < 0.016
    on = np.abs(p[..., 0] - GEO.centre_x_m) < GEO.width_m / 2
    light = 0.8 + 0.2 * np.cos((xs - 160) / 300.0)[..., None]
    img = np.where(on[..., None], np.where(stripe[..., None], 110.0, 42.0), 150.0) * light
    img = np.broadcast_to(img, (h, w, 3)).copy()
    if obj_at is not None:
        box = (np.abs(p[..., 0] - 0.8) < 0.05) & (np.abs(p[..., 1] - obj_at) < 0.04)
        img[box] = (30.0, 60.0, 170.0)
    return np.clip(img, 0, 255).astype(np.uint8)


@pytest.fixture(scope="module")
def belt() -> BeltBackground:
    travels = [k * GEO.loop_m / 16 + 0.013 for k in range(16)]  # steps shorter than the view
    return build_belt_background([(_render(t), t) for t in travels], camera=CAM,
                                 T_base_cam=_T_cam(), geometry=GEO)  # fmt: skip


def test_registered_background_matches_the_belt_at_any_travel(belt):
    for travel in (0.0, 0.377, 1.91, 5.3):  # also past one loop
        frame = _render(travel)
        diff = np.abs(frame.astype(int) - belt.at(travel).astype(int)).max(axis=2)
        assert np.percentile(diff, 97) <= 12, travel  # all but the stripes' edges (2 mm cells)
        with pytest.raises(SegmentationFailed):  # the empty belt is seen as empty
            foreground_mask(frame, belt.at(travel))
    # Against a still image of the empty belt at another travel its stripes are "objects".
    assert foreground_mask(_render(0.377), _render(0.013)).sum() > 1000


def test_an_object_on_the_moving_belt_is_found_whole_and_alone(belt):
    travel = 0.52
    mask = foreground_mask(_render(travel, obj_at=0.01), belt.at(travel))
    p = plane_points(np.argwhere(mask)[:, ::-1].astype(float), CAM, _T_cam(), GEO.surface_z_m)
    # The box's footprint (100 x 80 mm), not the stripes across the belt.
    assert np.ptp(p[:, 0]) == pytest.approx(0.10, abs=0.006)
    assert np.ptp(p[:, 1]) == pytest.approx(0.08, abs=0.006)
    assert float(p[:, 1].mean()) == pytest.approx(0.01, abs=0.002)


def test_the_pose_it_was_grabbed_from_is_checked(belt):
    assert belt.matches(_T_cam())
    T = _T_cam()
    T[1, 3] += 0.01
    assert not belt.matches(T)


def test_bad_inputs_are_refused(belt):
    with pytest.raises(InvalidInput, match="frames"):
        build_belt_background([(_render(0.0), 0.0)] * 2, camera=CAM, T_base_cam=_T_cam(),
                              geometry=GEO)  # fmt: skip
    with pytest.raises(InvalidInput, match="finite"):
        build_belt_background([(_render(0.0), math.nan)] * 5, camera=CAM, T_base_cam=_T_cam(),
                              geometry=GEO)  # fmt: skip
    with pytest.raises(InvalidInput, match="travel_m"):
        belt.at(math.inf)
    with pytest.raises(InvalidInput, match="width"):
        BeltGeometry(0.8, -1.3, 0.0, 0.45, 2.6)
