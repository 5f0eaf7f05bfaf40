"""Feature heights triangulated from a model's taught top views (vision.pose.structure)
and the pose fit that holds the features at them.

The scenes are synthetic: object points at known heights seen by the cell's top view (50 mm
off the station's vertical, turned with the camera roll) at four teach yaws and three rolls,
each point with its own descriptor, so the right heights are known exactly."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from tests.vision.test_bug_pose_parallax import CAM, STATION, SURFACE, TOP, _cam, _planar, _project
from vision.features.types import Features, Keypoints
from vision.pose import estimate_pose
from vision.pose.structure import (
    MAX_SPREAD_M,
    HeightCache,
    TaughtTopView,
    triangulate_heights,
)

YAWS_DEG = (0.0, 90.0, 180.0, -90.0)
ROLLS = (0.0, 2.094, -2.094)


def _points(seed: int, n: int) -> np.ndarray:
    """Object-frame points (N, 3): on the top face and at heights down to the belt."""
    rng = np.random.default_rng(seed)
    r = rng.uniform(0.01, 0.10, n)
    a = rng.uniform(-math.pi, math.pi, n)
    h = np.where(rng.random(n) < 0.4, TOP - SURFACE, rng.uniform(0.0, TOP - SURFACE, n))
    return np.c_[r * np.cos(a), r * np.sin(a), h]


def _descriptors(n: int, seed: int) -> np.ndarray:
    d = np.random.default_rng(seed).random((n, 64)).astype(np.float32)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def _features(xy: np.ndarray, desc: np.ndarray) -> Features:
    n = len(xy)
    kp = Keypoints(xy, np.full(n, 8.0), np.zeros(n), np.ones(n), np.zeros(n, np.int32))
    return Features(kp, desc, "test", "1", image_shape=(480, 640))


def _views(pts: np.ndarray, desc: np.ndarray, *, seed: int = 0, noise_px: float = 0.2,
           seen: float = 0.8) -> tuple[list[TaughtTopView], list[np.ndarray]]:  # fmt: skip
    """The taught top views of ``pts`` and, per view, the point index of each keypoint."""
    rng = np.random.default_rng(seed)
    views, ids = [], []
    vid = 1
    for yaw in YAWS_DEG:
        T_obj = _planar(math.radians(yaw), *STATION[:2])
        for roll in ROLLS:
            T_cam = _cam(roll)
            keep = np.flatnonzero(rng.random(len(pts)) < seen)
            world = pts[keep] @ T_obj[:3, :3].T + T_obj[:3, 3]
            xy = _project(T_cam, world) + rng.normal(0.0, noise_px, (len(keep), 2))
            d = desc[keep] + rng.normal(0.0, 0.01, desc[keep].shape).astype(np.float32)
            views.append(TaughtTopView(vid, _features(xy, d), T_cam, T_obj))
            ids.append(keep)
            vid += 1
    return views, ids


KW = dict(camera=CAM, z_floor_m=SURFACE, z_top_m=TOP)


def test_heights_of_the_taught_features_are_recovered():
    pts = _points(1, 150)
    views, ids = _views(pts, _descriptors(150, 1))
    fh = triangulate_heights(views, **KW)
    assert fh.pairs == 66
    errs = []
    for v, keep in zip(views, ids, strict=True):
        z = fh.by_view[v.view_id]
        assert z.shape == (len(keep),)
        got = np.isfinite(z)
        assert got.mean() > 0.7, got.mean()
        errs.append(np.abs(z[got] - (SURFACE + pts[keep[got], 2])))
    e = np.concatenate(errs)
    # 0.2 px of noise and baselines of 26-100 mm at 0.4 m: about 1-2 mm per pair
    p50, p95 = np.percentile(e, [50, 95])
    assert p50 < 0.0006 and p95 < 0.0015 and e.max() < 2 * MAX_SPREAD_M, (p50, p95, e.max())


def test_look_alike_features_round_a_circle_are_told_apart_by_the_epipolar_segment():
    """Six bolts with one descriptor (the pipe flange's): the ratio test over the whole view
    rejects every one of them, the candidates on the height-bounded epipolar segment hold
    one bolt each."""
    bolts = np.array([[0.06 * math.cos(a), 0.06 * math.sin(a), TOP - SURFACE]
                      for a in np.arange(6) * math.pi / 3])  # fmt: skip
    others = _points(2, 30)
    pts = np.vstack([bolts, others])
    desc = _descriptors(len(pts), 2)
    desc[:6] = desc[0]
    views, ids = _views(pts, desc, seed=3, seen=1.0)
    fh = triangulate_heights(views, **KW)
    for v, keep in zip(views, ids, strict=True):
        z = fh.by_view[v.view_id][keep < 6]
        assert np.count_nonzero(np.isfinite(z)) >= 5, z
        assert np.all(np.abs(z[np.isfinite(z)] - TOP) < 0.002), z


def test_a_feature_seen_by_too_few_views_or_matched_wrongly_gets_no_height():
    pts = _points(4, 40)
    desc = _descriptors(40, 4)
    views, ids = _views(pts, desc, seed=5, seen=1.0)
    # point 0 only in the first two views: one other view cannot outvote a wrong match
    lonely = []
    for k, (v, keep) in enumerate(zip(views, ids, strict=True)):
        if k >= 2:
            sel = keep != 0
            views[k] = TaughtTopView(v.view_id, v.features.take(sel), v.T_base_cam, v.T_base_obj)
            ids[k] = keep[sel]
        else:
            lonely.append(int(np.flatnonzero(keep == 0)[0]))
    fh = triangulate_heights(views, **KW)
    for k in range(2):
        assert math.isnan(fh.by_view[views[k].view_id][lonely[k]])
    # a view whose keypoints were put a tenth of a turn off: its features meet nobody's rays
    T_wrong = views[3].T_base_obj @ _planar(math.radians(36.0), 0.0, 0.0)
    T_wrong[:3, 3] = views[3].T_base_obj[:3, 3]
    views[3] = TaughtTopView(views[3].view_id, views[3].features, views[3].T_base_cam, T_wrong)
    fh = triangulate_heights(views, **KW)
    assert np.count_nonzero(np.isfinite(fh.by_view[views[3].view_id])) <= 2


def test_the_heights_are_looked_up_by_the_trained_pixels():
    pts = _points(6, 60)
    views, _ = _views(pts, _descriptors(60, 6), seed=7)
    fh = triangulate_heights(views, **KW)
    v = views[0]
    xy = v.features.keypoints.xy
    pick = np.array([3, 0, 7])
    got = fh.of(v.view_id, np.vstack([xy[pick], [[-5.0, -5.0]]]), xy)
    assert np.array_equal(got[:3], fh.by_view[v.view_id][pick], equal_nan=True)
    assert math.isnan(got[3])
    assert np.all(np.isnan(fh.of(999, xy[:2], xy)))


def test_a_pose_with_triangulated_heights_is_right_where_the_free_heights_trade_off():
    """The camera moved along the belt relative to the object (taught and seen from the same
    roll, the object shifted along y) and every feature far below the top face (the valve
    block's, under its solenoid's cap): a feature's parallax looks like a shift, so the fit
    with every height free between the belt and the top face leaves the pose off; with the
    heights the taught views triangulated it is right."""
    rng = np.random.default_rng(8)
    local = _points(8, 60)
    local[:, 2] = rng.uniform(0.01, 0.04, 60)
    taught = _planar(0.0, *STATION[:2])
    truth = _planar(0.0, STATION[0], STATION[1] + 0.03)
    T_view, T_now = _cam(0.0), _cam(0.0)
    pa = _project(T_view, local @ taught[:3, :3].T + taught[:3, 3])
    pb = _project(T_now, local @ truth[:3, :3].T + truth[:3, 3])
    pb = pb + rng.normal(0.0, 0.2, pb.shape)
    A, _ = cv2.estimateAffine2D(pa, pb)
    H = np.vstack([A, [0.0, 0.0, 1.0]])
    mask = np.zeros((480, 640), bool)
    lo, hi = pa.min(0).astype(int), pa.max(0).astype(int)
    mask[lo[1] : hi[1], lo[0] : hi[0]] = True
    kw = dict(camera=CAM, T_base_cam_view=T_view, T_base_cam_now=T_now,
              T_base_obj_taught=taught, z_plane_m=TOP, view_mask=mask, view_shape=(480, 640),
              inlier_xy=np.c_[pa, pb], z_floor_m=SURFACE)  # fmt: skip
    free = estimate_pose(H, **kw)
    known = estimate_pose(H, heights=SURFACE + local[:, 2] + rng.normal(0.0, 0.0007, 60), **kw)

    def err(p):
        return 1e3 * float(np.linalg.norm(p.T_base_obj[:2, 3] - truth[:2, 3]))

    assert known.method == free.method == "parallax"
    assert (known.triangulated, free.triangulated) == (60, 0)
    assert err(known) < 0.5 and err(free) > 2.0 * err(known) + 0.5, (err(free), err(known))


def test_the_cache_computes_once_per_set_of_views_and_calibration():
    pts = _points(9, 50)
    views, _ = _views(pts, _descriptors(50, 9), seed=9)
    cache = HeightCache(max_entries=2)
    a = cache.get(views, **KW)
    assert cache.get(list(reversed(views)), **KW) is a  # the order does not matter
    moved = [TaughtTopView(v.view_id, v.features, v.T_base_cam @ _planar(0.0, 0.001, 0.0)
                           @ np.linalg.inv(_planar(0.0, 0.0, 0.0)), v.T_base_obj)
             for v in views]  # fmt: skip
    b = cache.get(moved, **KW)
    assert b is not a
    cache.get(views[:6], **KW)
    assert len(cache) == 2
    assert cache.get(views, **KW) is not a  # the least recently used was dropped


@pytest.mark.parametrize("bad", [0, -1, 5000])
def test_the_cache_size_is_bounded(bad):
    with pytest.raises(ValueError, match="max_entries"):
        HeightCache(max_entries=bad)


@pytest.mark.parametrize("lo, hi", [(math.nan, TOP), (SURFACE, math.inf), (TOP, SURFACE)])
def test_heights_must_be_finite_and_ordered(lo, hi):
    with pytest.raises(ValueError, match="z_floor_m"):
        triangulate_heights([], camera=CAM, z_floor_m=lo, z_top_m=hi)


def test_matching_in_blocks_of_rows_gives_the_same_heights(monkeypatch):
    """The guided matching works through one view's features in blocks (bounded memory at
    any feature count); the blocks must not change the answer."""
    import vision.pose.structure as structure

    pts = _points(10, 90)
    views, _ = _views(pts, _descriptors(90, 10), seed=11)
    whole = triangulate_heights(views, **KW)
    monkeypatch.setattr(structure, "CHUNK_ROWS", 7)
    blocks = triangulate_heights(views, **KW)
    assert whole.triangulated > 0
    for vid, z in whole.by_view.items():
        assert np.array_equal(z, blocks.by_view[vid], equal_nan=True)
