"""The side views' region of interest from the top view (backend.inspection.roi): a known
camera and a known box, degenerate inputs, and the service's side view passing the region."""

from __future__ import annotations

import math
from types import SimpleNamespace

import cv2
import numpy as np
import pytest

from backend.calibration.autoplan import NOMINAL_T_EE_CAM
from backend.inspection import service
from backend.inspection.roi import height_bound, side_query, side_roi
from backend.recognition.teach import plan_shots
from robot.drivers.conveyor import FixedStation
from robot.kinematics import T_base_ee
from robot.sim.camera import CameraSpec
from robot.sim.world import ConveyorSpec
from vision.camera import PinholeCamera

W, H = 640, 480
CAM = PinholeCamera(np.array([[500.0, 0, 319.5], [0, 500.0, 239.5], [0, 0, 1]]), None,
                    width=W, height=H)  # fmt: skip
CAM_DIST = PinholeCamera(CAM.K, (-0.25, 0.08, 0.0, 0.0), width=W, height=H)


def _look_from(eye, target) -> np.ndarray:
    """T_base_cam of a camera at ``eye`` with +z towards ``target`` (OpenCV frame)."""
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0]) if abs(z[2]) < 0.99 else np.array([1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, :3] = np.stack([x, y, z], axis=1)
    T[:3, 3] = eye
    return T


def _box(centre, half, height) -> np.ndarray:
    """Points filling a box on the belt (corners, edges and the inside), (N, 3)."""
    g = np.linspace(-1.0, 1.0, 5)
    xx, yy, zz = np.meshgrid(g * half[0], g * half[1], (g + 1) / 2 * height)
    return np.stack([xx.ravel(), yy.ravel(), zz.ravel()], axis=1) + np.asarray(centre, float)


def _silhouette(cam, T_base_cam, pts) -> np.ndarray:
    uv = cam.project_world(pts, np.linalg.inv(T_base_cam))
    m = np.zeros((cam.height, cam.width), np.uint8)
    cv2.fillConvexPoly(m, cv2.convexHull(uv.round().astype(np.int32)), 1)
    return m.astype(bool)


def _inside(mask, cam, T_base_cam, pts) -> np.ndarray:
    uv = cam.project_world(pts, np.linalg.inv(T_base_cam)).round().astype(int)
    ok = (uv[:, 0] >= 0) & (uv[:, 0] < cam.width) & (uv[:, 1] >= 0) & (uv[:, 1] < cam.height)
    assert ok.all(), "test points must lie in the side image"
    return mask[uv[:, 1], uv[:, 0]].astype(bool)


T_TOP = _look_from([0.0, 0.0, 0.45], [0.0, 0.0, 0.0])
T_SIDE = _look_from([0.0, -0.3, 0.45], [0.0, 0.0, 0.05])  # about 34 deg off vertical
BOX = _box([0.01, -0.02, 0.0], (0.05, 0.04), 0.06)


@pytest.mark.parametrize("cam", [CAM, CAM_DIST], ids=["pinhole", "barrel"])
def test_region_holds_the_box_and_leaves_out_the_far_belt(cam):
    top = _silhouette(cam, T_TOP, BOX)
    roi = side_roi(top, camera=cam, T_base_cam_top=T_TOP, T_base_cam_side=T_SIDE,
                   surface_z_m=0.0, height_m=0.08, image_shape=(H, W))  # fmt: skip
    assert roi.mask is not None, roi.reason
    assert roi.mask.dtype == np.uint8 and roi.mask.shape == (H, W)
    assert _inside(roi.mask, cam, T_SIDE, BOX).all()
    far = np.array([[0.2, 0.0, 0.0], [-0.2, 0.05, 0.0], [0.0, 0.22, 0.0], [0.0, -0.12, 0.0],
                    [0.15, 0.15, 0.0]])  # fmt: skip
    assert not _inside(roi.mask, cam, T_SIDE, far).any()
    assert 0.02 < roi.fraction < 0.5
    assert roi.mask.mean() == pytest.approx(roi.fraction)
    img = np.zeros((H, W, 3), np.uint8)
    got = side_query(img, roi)
    assert isinstance(got, tuple) and got[1] is roi.mask


def test_taller_bound_and_belt_motion_move_the_region():
    top = _silhouette(CAM, T_TOP, BOX)
    kw = dict(camera=CAM, T_base_cam_top=T_TOP, T_base_cam_side=T_SIDE, surface_z_m=0.0,
              image_shape=(H, W))  # fmt: skip
    low = side_roi(top, height_m=0.06, **kw)
    high = side_roi(top, height_m=0.2, **kw)
    assert high.fraction > low.fraction
    # the taller space holds the lower one (up to the edges' growth by the margin)
    assert (low.mask > high.mask).sum() < 0.01 * low.mask.sum()
    moved = side_roi(top, height_m=0.06, moved_m=(0.0, 0.08, 0.0), **kw)
    tall_box_moved = BOX + np.array([0.0, 0.08, 0.0])
    assert _inside(moved.mask, CAM, T_SIDE, tall_box_moved).all()
    assert not _inside(low.mask, CAM, T_SIDE, tall_box_moved).all()


def test_degenerate_views_fall_back_to_the_whole_frame_and_say_why():
    kw = dict(camera=CAM, T_base_cam_top=T_TOP, T_base_cam_side=T_SIDE, surface_z_m=0.0,
              height_m=0.08, image_shape=(H, W))  # fmt: skip
    empty = side_roi(np.zeros((H, W), bool), **kw)
    assert empty.mask is None and empty.fraction == 1.0 and "empty" in empty.reason
    speck = np.zeros((H, W), bool)
    speck[240, 100:103] = True
    r = side_roi(speck, **kw)
    assert r.mask is None and r.reason.startswith("whole frame")
    top = _silhouette(CAM, T_TOP, BOX)
    up = _look_from([0.0, 0.0, 0.45], [0.0, 0.0, 1.0])  # looking up: the belt is behind
    r = side_roi(top, **{**kw, "T_base_cam_top": up})
    assert r.mask is None and "miss the belt" in r.reason
    behind = _look_from([0.0, -0.3, 0.45], [0.0, -0.6, 0.45])  # side camera facing away
    r = side_roi(top, **{**kw, "T_base_cam_side": behind})
    assert r.mask is None and "behind" in r.reason
    aside = _look_from([1.0, -0.3, 0.45], [1.0, 0.0, 0.05])  # looking at another spot
    r = side_roi(top, **{**kw, "T_base_cam_side": aside})
    assert r.mask is None and "off the side image" in r.reason
    r = side_roi(top, **{**kw, "image_shape": (240, 320)})
    assert r.mask is None and "camera model" in r.reason


@pytest.mark.parametrize(
    "change, match",
    [
        ({"top_mask": np.zeros((H, W), np.float32)}, "top_mask"),
        ({"top_mask": np.zeros((H, W, 3), bool)}, "top_mask"),
        ({"T_base_cam_top": np.full((4, 4), np.nan)}, "T_base_cam_top"),
        ({"T_base_cam_side": np.eye(4) * 2}, "rigid"),
        ({"height_m": 0.0}, "height_m"),
        ({"height_m": math.nan}, "height_m"),
        ({"height_m": True}, "height_m"),
        ({"surface_z_m": math.inf}, "surface_z_m"),
        ({"margin_m": -0.01}, "margin_m"),
        ({"margin_px": 2.5}, "margin_px"),
        ({"image_shape": (480,)}, "image_shape"),
        ({"moved_m": (0.0, math.nan, 0.0)}, "moved_m"),
    ],
)
def test_bad_inputs_are_refused(change, match):
    kw = dict(top_mask=_silhouette(CAM, T_TOP, BOX), camera=CAM, T_base_cam_top=T_TOP,
              T_base_cam_side=T_SIDE, surface_z_m=0.0, height_m=0.08, image_shape=(H, W))  # fmt: skip
    kw.update(change)
    top = kw.pop("top_mask")
    with pytest.raises(ValueError, match=match):
        side_roi(top, **kw)


def test_height_bound_takes_the_tallest_model_or_the_default():
    assert height_bound([0.05, 0.12, 0.08]) == pytest.approx(0.12)
    assert height_bound([0.05, None], default_m=0.3) == pytest.approx(0.3)
    assert height_bound([], default_m=0.2) == pytest.approx(0.2)
    with pytest.raises(ValueError, match="finite"):
        height_bound([math.nan])
    with pytest.raises(ValueError, match=r"\(0, 1\]"):
        height_bound([2.0])
    with pytest.raises(ValueError, match="default_m"):
        height_bound([0.1], default_m=0.0)


class _Cell:
    """Answers ``look(q)`` with a blank frame taken at ``q`` (the arm reached it)."""

    def __init__(self) -> None:
        self.looked: list[np.ndarray] = []

    async def look(self, q, *, speed=None):
        self.looked.append(np.asarray(q))
        return SimpleNamespace(rgb=np.zeros((H, W, 3), np.uint8), meta={},
                               robot_state=SimpleNamespace(q=np.asarray(q)))  # fmt: skip


@pytest.mark.parametrize("vp", [2, 3])
async def test_the_services_side_view_passes_the_region_as_the_query_mask(vp):
    spec = CameraSpec()
    cam, T_ee_cam = spec.pinhole, np.asarray(spec.T_ee_cam)
    belt = ConveyorSpec()
    station = np.asarray(belt.station_point, float)
    top = plan_shots(station, (1,), T_ee_cam=np.asarray(NOMINAL_T_EE_CAM), object_height_m=0.1,
                     top_rolls_rad=(0.0,))[0]  # fmt: skip
    T_top = T_base_ee(np.asarray(top.q)) @ T_ee_cam
    base = np.array([station[0], station[1], belt.surface_z_m])
    box = _box(base, (0.06, 0.05), 0.09)
    rt = SimpleNamespace(cell=_Cell(), conveyor=FixedStation())
    ctx = service._Ctx(rt, cam, T_ee_cam, "test", station, float(belt.surface_z_m))
    side = await service._side_view(
        ctx, vp, station, T_plan=np.asarray(NOMINAL_T_EE_CAM), top_mask=_silhouette(cam, T_top, box),
        T_cam_top=T_top, height_m=0.1, travel0=None, speed=None,
    )  # fmt: skip
    assert len(rt.cell.looked) == 1
    assert side.roi.mask is not None, side.roi.reason
    assert _inside(side.roi.mask, cam, side.T_base_cam, box).all()
    assert side.roi.fraction < 0.6
    got = side_query(side.frame.rgb, side.roi)
    assert isinstance(got, tuple) and got[1].shape == (H, W) and got[1].any()
