"""The empty belt's background at any travel (vision.segmentation.belt) against a belt
whose pattern is known: a plain belt with one bright cross stripe, rendered exactly."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vision.camera import PinholeCamera
from vision.errors import InvalidInput
from vision.pose import plane_points
from vision.segmentation.belt import CELL_M, BeltGeometry, build_belt_background

W, H = 80, 60
#: 1.7 mm per pixel on the belt 1 m below (finer than the mosaic's 2 mm cells): 0.13 m x
#: 0.1 m of the belt and of the floor beside it.
CAM = PinholeCamera(np.array([[600.0, 0.0, 39.5], [0.0, 600.0, 29.5], [0.0, 0.0, 1.0]]))
GEOMETRY = BeltGeometry(centre_x_m=0.0, start_y_m=0.0, width_m=0.1, surface_z_m=0.0, loop_m=1.0)
#: Frames of the empty belt: 40 travels 25 mm apart, so that the 0.1 m of the belt in view
#: sweeps the whole loop.
TRAVELS = [0.025 * k for k in range(40)]
#: The stripe runs across the belt over belt coordinates u in [0.10, 0.16) m.
STRIPE_M = (0.10, 0.16)
PLAIN, BRIGHT, FLOOR = 100, 200, 60


def _T_cam() -> np.ndarray:
    """A camera 1 m above (0, 0.5) looking straight down (OpenCV frame)."""
    T = np.diag([1.0, -1.0, -1.0, 1.0])
    T[:3, 3] = (0.0, 0.5, 1.0)
    return T


def _ground() -> np.ndarray:
    ys, xs = np.mgrid[0:H, 0:W]
    px = np.stack([xs.ravel(), ys.ravel()], axis=1).astype(np.float64)
    return plane_points(px, CAM, _T_cam(), 0.0).reshape(H, W, 3)


GROUND = _ground()
ON_BELT = np.abs(GROUND[..., 0]) < GEOMETRY.width_m / 2
#: Pixels within 4 mm of the belt's edges (the background keeps 3 mm off them).
NEAR_EDGE = np.abs(np.abs(GROUND[..., 0]) - GEOMETRY.width_m / 2) < 0.004


def _render(travel_m: float) -> np.ndarray:
    """The exact image of the belt after ``travel_m``: the floor beside it, the belt plain
    but for the stripe, which has moved ``travel_m`` along +y (modulo the loop)."""
    u = np.mod(GROUND[..., 1] - GEOMETRY.start_y_m - travel_m, GEOMETRY.loop_m)
    stripe = (u >= STRIPE_M[0]) & (u < STRIPE_M[1])
    img = np.where(ON_BELT, np.where(stripe, BRIGHT, PLAIN), FLOOR).astype(np.uint8)
    return np.repeat(img[..., None], 3, axis=2)


def _stripe_inside(travel_m: float, margin_m: float) -> np.ndarray:
    """Belt pixels at least ``margin_m`` inside the stripe at ``travel_m``."""
    u = np.mod(GROUND[..., 1] - travel_m, GEOMETRY.loop_m)
    inside = (u >= STRIPE_M[0] + margin_m) & (u < STRIPE_M[1] - margin_m)
    return inside & ON_BELT


@pytest.fixture(scope="module")
def belt():
    return build_belt_background([(_render(t), t) for t in TRAVELS], camera=CAM,
                                 T_base_cam=_T_cam(), geometry=GEOMETRY)  # fmt: skip


def test_the_static_part_is_the_belt_without_its_stripe(belt):
    # The stripe covers any one pixel in at most three of the 40 frames: the median is the
    # plain belt, and the floor beside the belt is what every frame saw.
    static = belt.static[..., 0]
    assert ON_BELT.any() and (~ON_BELT).any()
    assert np.all(static[ON_BELT] == PLAIN)
    assert np.all(static[~ON_BELT] == FLOOR)
    assert belt.frames == len(TRAVELS)


def test_the_mosaic_holds_the_stripe_at_its_belt_coordinates(belt):
    # Ratio to the static view: BRIGHT / PLAIN = 2 inside the stripe, 1 on the plain belt.
    nv, nu, _ = belt.ratio.shape
    assert (nv, nu) == (
        math.ceil(GEOMETRY.width_m / CELL_M) + 1,
        math.ceil(GEOMETRY.loop_m / CELL_M),
    )
    # the mosaic's row of the image's column 40
    lateral = GROUND[H // 2, W // 2, 0] + GEOMETRY.width_m / 2
    row = belt.ratio[round(lateral / CELL_M), :, 0]
    u = np.arange(nu) * CELL_M
    inside = (u >= STRIPE_M[0] + 0.01) & (u < STRIPE_M[1] - 0.01)
    plain = (u < STRIPE_M[0] - 0.01) | (u >= STRIPE_M[1] + 0.01)
    assert inside.sum() == 20
    np.testing.assert_allclose(row[inside], BRIGHT / PLAIN, rtol=1e-6)
    np.testing.assert_allclose(row[plain], 1.0, rtol=1e-6)


# The camera sees belt coordinates y - travel for y in [0.45, 0.55] m: the stripe from a
# travel of about 0.29 m to 0.45 m (modulo the loop); none of these is a frame's travel.
@pytest.mark.parametrize(
    ("travel_m", "stripe_px"), [(0.34, 200), (0.362, 200), (0.38, 200), (3.36, 200), (0.8, 0)]
)
def test_the_background_at_a_travel_is_the_belt_seen_then(belt, travel_m, stripe_px):
    got = belt.at(travel_m)[..., 0].astype(int)
    want = _render(travel_m)[..., 0].astype(int)
    inside = _stripe_inside(travel_m, 0.01) & ~NEAR_EDGE
    assert (inside.sum() >= stripe_px) if stripe_px else not inside.any()
    np.testing.assert_array_equal(got[inside], BRIGHT)
    # Away from the stripe's two edges (a 2 mm cell and a bilinear step) and from the
    # belt's, exact.
    edge = (_stripe_inside(travel_m, -0.01) & ~_stripe_inside(travel_m, 0.01)) | NEAR_EDGE
    np.testing.assert_array_equal(got[~edge], want[~edge])


def test_it_applies_to_the_camera_pose_it_was_grabbed_from(belt):
    assert belt.matches(_T_cam())
    moved = _T_cam()
    moved[0, 3] += 0.01  # beyond its 2 mm tolerance
    assert not belt.matches(moved)


@pytest.mark.parametrize(
    "kw",
    [
        dict(width_m=0.01),
        dict(loop_m=1000.0),
        dict(surface_z_m=math.nan),
        dict(centre_x_m=math.inf),
    ],
)
def test_bad_geometry_is_refused(kw):
    base = dict(centre_x_m=0.0, start_y_m=0.0, width_m=0.4, surface_z_m=0.0, loop_m=1.0)
    with pytest.raises(InvalidInput):
        BeltGeometry(**{**base, **kw})


def test_bad_frames_and_travels_are_refused(belt):
    frame = _render(0.0)
    with pytest.raises(InvalidInput, match=r"5\.\.64 frames"):
        build_belt_background([(frame, 0.0)] * 4, camera=CAM, T_base_cam=_T_cam(),
                              geometry=GEOMETRY)  # fmt: skip
    with pytest.raises(InvalidInput, match="HxWx3 uint8"):
        build_belt_background([(frame[..., 0], 0.0)] * 5, camera=CAM, T_base_cam=_T_cam(),
                              geometry=GEOMETRY)  # fmt: skip
    with pytest.raises(InvalidInput, match="finite"):
        build_belt_background([(frame, math.inf)] * 5, camera=CAM, T_base_cam=_T_cam(),
                              geometry=GEOMETRY)  # fmt: skip
    with pytest.raises(InvalidInput, match="travel_m"):
        belt.at(math.nan)
