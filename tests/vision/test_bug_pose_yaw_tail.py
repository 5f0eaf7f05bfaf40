"""Bug: the pipe flange's yaw passed 1 degree on a few inspections in a hundred.

Its top view holds few correspondences (6-20 per trained view), a keypoint with two
dominant orientations gave the same correspondence twice (counted twice in the fit), and
some correspondences do not move rigidly with the part: shading on its round steel tube
stays with the lights while the part turns.  The robust loss (soft-L1 beyond 1.5 px) only
lessened their pull, and with few correspondences left the yaw followed them
(``benchmarks.inspection --parts pipe-flange --seed 5``: 3 of 106 past 1 degree, the worst
1.12).  The fix counts a repeated correspondence once, narrows the loss to 0.75 px and
drops what the first fit leaves beyond the verification's 3 px before fitting again.
"""

from __future__ import annotations

import math

import numpy as np

from tests.vision.test_bug_pose_parallax import SURFACE, TOP, _cam, _observed, _planar, _project
from vision.pose import estimate_pose

#: How far the shading lags the part's turn, degrees (3-5 px at the bolt circle).
LAG_DEG = 4.0


def _flange(yaw_now: float, dx: float, dy: float, roll_view: float, n_stuck: int, seed: int):
    """A flange-like part: a few features on a bolt circle and a tube, ``n_stuck`` of
    them shading that lags the part's turn by :data:`LAG_DEG` (it stays with the lights
    while the surface under it turns)."""
    rng = np.random.default_rng(seed)
    n = 16
    r = np.r_[rng.uniform(0.06, 0.07, 8), rng.uniform(0.04, 0.05, 8)]
    a = rng.uniform(-math.pi, math.pi, n)
    h = np.r_[np.full(8, 0.026), rng.uniform(0.08, TOP - SURFACE, 8)]
    local = np.c_[r * np.cos(a), r * np.sin(a), h, np.ones(n)]
    station = np.array([0.8, 0.0])
    taught = _planar(math.radians(90), *station)
    truth = _planar(math.radians(90) + yaw_now, station[0] + dx, station[1] + dy)
    lagging = _planar(math.radians(90 - LAG_DEG) + yaw_now, station[0] + dx, station[1] + dy)
    T_view, T_now = _cam(roll_view), _cam(0.0)
    pa = _project(T_view, (local @ taught.T)[:, :3])
    moved = local @ truth.T
    moved[:n_stuck] = local[:n_stuck] @ lagging.T
    pb = _project(T_now, moved[:, :3]) + rng.normal(0, 0.4, (n, 2))
    return (*_observed(pa, pb, T_view, T_now, taught, robust=False), truth)


def _yaw_err_deg(pose, truth) -> float:
    d = pose.yaw_rad - math.atan2(truth[1, 0], truth[0, 0])
    return abs(math.degrees(math.remainder(d, 2 * math.pi)))


def test_shading_that_does_not_turn_with_the_part_is_dropped():
    worst = []
    for seed in range(6):
        H, pairs, kw, truth = _flange(math.radians(25), 0.002, -0.003, 2.094, 3, seed)
        pose = estimate_pose(H, **kw, inlier_xy=pairs, z_floor_m=SURFACE)
        assert pose.method == "parallax"
        assert pose.n_points < len(pairs)  # those off by more than 3 px left out
        worst.append(_yaw_err_deg(pose, truth))
    # before the fix: 0.09-0.79 degrees over these six (four past 0.35); after: under 0.15
    assert max(worst) < 0.25, worst


def test_a_correspondence_listed_twice_counts_once():
    H, pairs, kw, truth = _flange(math.radians(-40), -0.001, 0.002, -2.094, 0, 11)
    twice = np.r_[pairs, pairs[:5]]
    pose = estimate_pose(H, **kw, inlier_xy=twice, z_floor_m=SURFACE)
    assert pose.method == "parallax"
    assert pose.n_points == len(pairs)
    assert _yaw_err_deg(pose, truth) < 0.25
