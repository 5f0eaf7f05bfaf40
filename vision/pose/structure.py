"""Heights of a model's trained features, triangulated from its taught top views.

The pose's joint fit (:func:`vision.pose.refine_with_parallax`) places each
correspondence's trained feature on its trained viewing ray at an unknown height, bounded
between the belt and the top face.  From one current view a feature's height and the
object's shift trade off against each other (the parallax of a camera that moved along the
belt looks like a shift), so that fit leans on a weak pull of every height towards the top
face and on the other trained views' correspondences.  But a feature's height is a property
of the model, not of the inspection: every taught top view was taken from a known camera
pose (its joints through the hand-eye transform) with the object in a known frame (the
station turned by the teach's yaw): three camera rolls per teach round, 12 or 24 views
from camera places up to about 100 mm apart relative to the object.  A feature matched
between two of them is triangulated in the object's frame (the midpoint of the two viewing
rays' common perpendicular; Hartley and Zisserman, *Multiple View Geometry*, 2nd ed.,
2003, chapter 12), and the fit then holds it near that height instead of guessing.

The features are matched with the known geometry (guided matching; Hartley and Zisserman,
section 11.6 applied to a known pair of poses): a feature of one view can only be seen in
the other on the part of its epipolar line between where its ray meets the belt and where it
meets the top face, so its candidates are the other view's features within
:data:`EPIPOLAR_PX` of that segment, and the ratio test (Lowe 2004, section 7.1) is taken
among those candidates only.  A plain ratio test over the whole view keeps almost nothing of
a part whose features repeat (a flange's bolts all look alike, so the nearest and the
second nearest are two bolts); the segment holds one bolt.  The nearest candidate must also be
nearly as close in descriptor as the nearest feature anywhere in the other view, and the
match mutual.  A match counts only if the two rays pass within :data:`MAX_GAP_PX` (in pixels
at the point's depth), meet at :data:`MIN_ANGLE_RAD` or more (a narrower angle leaves the
depth undetermined) and land between the belt and the top face.  A feature keeps
a height only when at least :data:`MIN_VOTES` of its other views agree within
:data:`MAX_SPREAD_M` of their median.  With 1 px of noise, rays 10 deg apart at 0.4 m fix the
height to about 2 mm; the median of several pairs to better.

The result depends only on the taught views and the calibration, so it is computed once
per model and kept (:class:`HeightCache`), keyed by the views' features and the poses.
"""

from __future__ import annotations

import hashlib
import math
import threading
from collections import OrderedDict
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from vision.camera import PinholeCamera
from vision.features.types import Features
from vision.pose.geometry import closest_points, object_rays

__all__ = [
    "FeatureHeights",
    "HeightCache",
    "TaughtTopView",
    "triangulate_heights",
]

#: Largest distance of a candidate from the other view's height-bounded epipolar segment,
#: pixels.
EPIPOLAR_PX = 1.5
#: Ratio test among a feature's epipolar candidates (Lowe 2004: 0.8).
RATIO = 0.8
#: Largest distance between the two rays at the point, in pixels at its depth in the nearer
#: camera (the verification's inlier bound is 3 px; triangulated points are held tighter).
MAX_GAP_PX = 1.0
#: Smallest angle between the two rays: below it the depth is not determined.
MIN_ANGLE_RAD = math.radians(2.0)
#: Fewest other views whose triangulations of a feature agree for it to keep a height.
MIN_VOTES = 2
#: Largest distance from the median of a feature's heights that still agrees, metres.
MAX_SPREAD_M = 0.002
#: Slack below the belt and above the top face for a triangulated height, metres.
HEIGHT_SLACK_M = 0.003
#: Most taught views triangulated together (pairs grow as the square).
MAX_VIEWS = 24
#: Features of one view matched at a time against the other's (bounds the working arrays:
#: a block of rows by the other view's features, at most 4,000 each).
CHUNK_ROWS = 256


@dataclass(frozen=True, eq=False)
class TaughtTopView:
    """A taught top view of a model: its features and where camera and object stood.

    Attributes
    ----------
    view_id : int
    features : Features
        Keypoints in pixels of the trained image and their descriptors.
    T_base_cam : ndarray of shape (4, 4)
        Camera pose of the shot (OpenCV convention, +z forward), base frame.
    T_base_obj : ndarray of shape (4, 4)
        The model's frame as the shot saw it (the station turned by the teach's yaw).
    """

    view_id: int
    features: Features
    T_base_cam: NDArray[np.float64]
    T_base_obj: NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class FeatureHeights:
    """Triangulated heights of a model's trained top-view features.

    Attributes
    ----------
    by_view : dict of int to ndarray of shape (N,)
        Per view id, the base-frame height (metres) of each keypoint, ``nan`` where none
        was triangulated.
    pairs : int
        View pairs matched.
    """

    by_view: dict[int, NDArray[np.float64]]
    pairs: int

    @property
    def triangulated(self) -> int:
        """Features with a height, over every view."""
        return int(sum(np.count_nonzero(np.isfinite(z)) for z in self.by_view.values()))

    def of(
        self, view_id: int, xy: NDArray[np.float64], keypoints_xy: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """Heights (M,) of the trained pixels ``xy`` (M, 2) of view ``view_id`` whose
        keypoints are ``keypoints_xy`` (N, 2): ``nan`` for a pixel that is not one of them
        or has no height."""
        z = self.by_view.get(view_id)
        out = np.full(len(xy), np.nan)
        if z is None or len(z) != len(keypoints_xy) or not len(xy):
            return out
        at = {(float(x), float(y)): i for i, (x, y) in enumerate(keypoints_xy)}
        for k, (x, y) in enumerate(np.asarray(xy, dtype=np.float64)):
            i = at.get((float(x), float(y)))
            if i is not None:
                out[k] = z[i]
        return out


#: A view's camera centre (3,), unit viewing rays of its keypoints (N, 3) and camera
#: rotation (3, 3), all in its object frame.
_Rays = tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]


def triangulate_heights(
    views: Sequence[TaughtTopView],
    *,
    camera: PinholeCamera,
    z_floor_m: float,
    z_top_m: float,
    progress: Callable[[int, int], None] | None = None,
) -> FeatureHeights:
    """Triangulate the features of a model's taught top views (module docstring).

    Parameters
    ----------
    views : sequence of TaughtTopView
        At most :data:`MAX_VIEWS`; the first ones are kept beyond that.
    camera : PinholeCamera
        Active intrinsics (``K``, ``dist``), the ones the views' poses were calibrated with.
    z_floor_m, z_top_m : float
        Base-frame heights of the belt surface and the model's top face, metres.
    progress : callable, optional
        Called with ``(pairs done, pairs)``.

    Returns
    -------
    FeatureHeights

    Raises
    ------
    ValueError
        Non-finite or inverted heights.
    """
    if not (math.isfinite(z_floor_m) and math.isfinite(z_top_m) and z_floor_m <= z_top_m):
        raise ValueError(
            f"z_floor_m <= z_top_m must both be finite, got {z_floor_m!r} and {z_top_m!r}"
        )
    views = list(views)[:MAX_VIEWS]
    f = float(camera.K[0, 0])
    rays = [object_rays(v.features.keypoints.xy, camera, v.T_base_cam, v.T_base_obj) for v in views]
    lo, hi = z_floor_m - HEIGHT_SLACK_M, z_top_m + HEIGHT_SLACK_M
    descs = [_descriptors(v.features) for v in views]
    # votes[i]: (keypoint index, height, other view) of every accepted triangulation
    votes: list[list[NDArray[np.float64]]] = [[] for _ in views]
    todo = [(i, j) for i in range(len(views)) for j in range(i + 1, len(views))]
    for done, (i, j) in enumerate(todo, 1):
        if len(views[i].features) >= 2 and len(views[j].features) >= 2:
            ia, jb = _guided_matches(rays[i], rays[j], descs[i], descs[j],
                                     views[i].T_base_obj, f, lo, hi)  # fmt: skip
            if len(ia):
                _pair(rays[i], rays[j], views[i].T_base_obj, ia, jb, f, lo, hi,
                      votes[i], votes[j], i, j)  # fmt: skip
        if progress is not None:
            progress(done, len(todo))
    by_view = {}
    for v, got in zip(views, votes, strict=True):
        by_view[v.view_id] = _agreed(got, len(v.features))
    return FeatureHeights(by_view, len(todo))


def _descriptors(features: Features) -> tuple[NDArray[np.float32], bool]:
    """Descriptors as float rows (binary ones unpacked to bits) and whether they were binary."""
    d = np.asarray(features.descriptors)
    if features.binary:
        return np.unpackbits(d.astype(np.uint8), axis=1).astype(np.float32), True
    return d.astype(np.float32, copy=False), False


def _distances(
    a: tuple[NDArray[np.float32], bool], b: tuple[NDArray[np.float32], bool]
) -> NDArray[np.float64]:
    """Descriptor distances (N_a, N_b): L2, or Hamming for unpacked bits (the squared L2 of
    0/1 vectors)."""
    A, B = a[0].astype(np.float64), b[0].astype(np.float64)
    sq = np.maximum(
        np.sum(A * A, axis=1)[:, None] + np.sum(B * B, axis=1)[None, :] - 2.0 * A @ B.T, 0.0
    )
    return sq if a[1] else np.sqrt(sq)


def _guided_matches(
    ri: _Rays,
    rj: _Rays,
    di: tuple[NDArray[np.float32], bool],
    dj: tuple[NDArray[np.float32], bool],
    T_base_obj: NDArray[np.float64],
    f: float,
    lo: float,
    hi: float,
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Matches of view i's features to view j's along their height-bounded epipolar
    segments (module docstring): indices into i and into j."""
    oi, Di, _ = ri
    oj, Dj, _ = rj
    T = np.asarray(T_base_obj, np.float64)
    r3, t3 = T[2, :3], float(T[2, 3])
    # each ray of i cut at the two bounding heights, in the object frame
    rd = Di @ r3
    ok_ray = np.abs(rd) > 1e-9
    rd = np.where(ok_ray, rd, 1.0)
    s_lo, s_hi = (lo - t3 - r3 @ oi) / rd, (hi - t3 - r3 @ oi) / rd
    ok_ray &= (s_lo > 0) & (s_hi > 0)
    # their projections into j's normalised image plane (X_cam = R^T (X - o), as rows)
    R_obj_camj = rj[2]
    ends = []
    for s_ in (s_lo, s_hi):
        Xc = (oi + s_[:, None] * Di - oj) @ R_obj_camj
        zc = np.where(np.abs(Xc[:, 2]) < 1e-9, 1e-9, Xc[:, 2])
        ok_ray &= Xc[:, 2] > 1e-6
        ends.append(Xc[:, :2] / zc[:, None])
    A, B = ends
    Pj = Dj @ R_obj_camj
    nj = Pj[:, :2] / Pj[:, 2:3]
    AB = B - A
    L2 = np.maximum(np.sum(AB * AB, axis=1), 1e-18)
    n_i, n_j = len(A), len(nj)
    d1, d2 = np.full(n_i, np.inf), np.full(n_i, np.inf)
    b1, glob_i = np.zeros(n_i, np.int64), np.full(n_i, np.inf)
    glob_j, best_j = np.full(n_j, np.inf), np.full(n_j, np.inf)
    back = np.full(n_j, -1, np.int64)
    # rows of i in blocks, so that the (block, N_j) arrays stay small at any feature count
    for r0 in range(0, n_i, CHUNK_ROWS):
        r1 = min(n_i, r0 + CHUNK_ROWS)
        # distance of every j point from each i segment of the block, pixels
        rel = nj[None, :, :] - A[r0:r1, None, :]
        u = np.clip(np.einsum("ijk,ik->ij", rel, AB[r0:r1]) / L2[r0:r1, None], 0.0, 1.0)
        diff = rel - u[..., None] * AB[r0:r1, None, :]
        near = (f * np.sqrt(np.sum(diff * diff, axis=2)) <= EPIPOLAR_PX) & ok_ray[r0:r1, None]
        dd = _distances((di[0][r0:r1], di[1]), dj)
        glob_i[r0:r1] = dd.min(axis=1)
        np.minimum(glob_j, dd.min(axis=0), out=glob_j)
        dc = np.where(near, dd, np.inf)
        rows = np.arange(r1 - r0)
        order = np.argsort(dc, axis=1)[:, :2]
        b1[r0:r1] = order[:, 0]
        d1[r0:r1] = dc[rows, order[:, 0]]
        if n_j > 1:
            d2[r0:r1] = dc[rows, order[:, 1]]
        col = np.argmin(dc, axis=0)
        col_d = dc[col, np.arange(n_j)]
        better = col_d < best_j
        best_j[better] = col_d[better]
        back[better] = col[better] + r0
    rows = np.arange(n_i)
    keep = (
        np.isfinite(d1)
        & (d1 < RATIO * d2)
        & (RATIO * d1 <= glob_i)
        & (RATIO * d1 <= glob_j[b1])
        & (back[b1] == rows)
    )
    ia = rows[keep].astype(np.int64)
    return ia, b1[keep].astype(np.int64)


def _pair(
    ri: _Rays,
    rj: _Rays,
    T_base_obj: NDArray[np.float64],
    ia: NDArray[np.int64],
    jb: NDArray[np.int64],
    f: float,
    lo: float,
    hi: float,
    votes_i: list[NDArray[np.float64]],
    votes_j: list[NDArray[np.float64]],
    i: int,
    j: int,
) -> None:
    """Triangulate the matches ``ia`` <-> ``jb`` of two views and add the accepted ones'
    heights to both views' votes."""
    oi, Di, _ = ri
    oj, Dj, _ = rj
    P1, P2, s, t, sin2 = closest_points(np.broadcast_to(oi, (len(ia), 3)), Di[ia],
                                        np.broadcast_to(oj, (len(jb), 3)), Dj[jb])  # fmt: skip
    ok = sin2 > math.sin(MIN_ANGLE_RAD) ** 2
    X = 0.5 * (P1 + P2)
    gap = np.linalg.norm(P1 - P2, axis=1)
    near = np.minimum(s, t)
    ok &= near > 0
    gap_px = f * 0.5 * gap / np.where(near > 0, near, 1.0)
    ok &= gap_px <= MAX_GAP_PX
    z = X @ np.asarray(T_base_obj, np.float64)[2, :3] + float(T_base_obj[2, 3])
    ok &= (z >= lo) & (z <= hi)
    if not ok.any():
        return
    votes_i.append(np.stack([ia[ok], z[ok], np.full(ok.sum(), j)], axis=1).astype(np.float64))
    votes_j.append(np.stack([jb[ok], z[ok], np.full(ok.sum(), i)], axis=1).astype(np.float64))


def _agreed(got: list[NDArray[np.float64]], n: int) -> NDArray[np.float64]:
    """Per keypoint, the median of its heights where at least :data:`MIN_VOTES` other
    views agree within :data:`MAX_SPREAD_M` of it (``nan`` elsewhere)."""
    out = np.full(n, np.nan)
    if not got:
        return out
    v = np.concatenate(got)
    order = np.argsort(v[:, 0], kind="stable")
    v = v[order]
    keys, starts = np.unique(v[:, 0].astype(np.int64), return_index=True)
    ends = np.append(starts[1:], len(v))
    for k, s, e in zip(keys, starts, ends, strict=True):
        if e - s < MIN_VOTES:
            continue
        z = v[s:e, 1]
        med = float(np.median(z))
        agree = np.abs(z - med) <= MAX_SPREAD_M
        if np.count_nonzero(agree) >= MIN_VOTES and np.count_nonzero(agree) * 3 >= 2 * (e - s):
            out[k] = float(np.median(z[agree]))
    return out


def _fingerprint(
    views: Sequence[TaughtTopView], camera: PinholeCamera, z: tuple[float, float]
) -> str:
    h = hashlib.blake2b(digest_size=16)
    for v in views:
        h.update(str(v.view_id).encode())
        h.update(np.ascontiguousarray(v.features.keypoints.xy).tobytes())
        h.update(np.ascontiguousarray(v.T_base_cam, np.float64).tobytes())
        h.update(np.ascontiguousarray(v.T_base_obj, np.float64).tobytes())
    h.update(np.ascontiguousarray(camera.K, np.float64).tobytes())
    h.update(np.ascontiguousarray(camera.dist, np.float64).tobytes())
    h.update(np.asarray(z, np.float64).tobytes())
    return h.hexdigest()


class HeightCache:
    """Triangulated heights per model, computed once for a set of views and a calibration.

    The key covers everything the result depends on (each view's id, keypoints and poses,
    the intrinsics and the heights), so a view taught again, deleted or calibrated anew
    gives a new entry; the least recently used beyond ``max_entries`` is dropped.  Safe to
    use from several threads (one computation per key at a time).
    """

    def __init__(self, max_entries: int = 32) -> None:
        if not 1 <= int(max_entries) <= 4096:
            raise ValueError(f"max_entries must be within 1 to 4096, got {max_entries!r}")
        self._max = int(max_entries)
        self._entries: OrderedDict[str, FeatureHeights] = OrderedDict()
        self._lock = threading.Lock()
        self._computing = threading.Lock()

    def __len__(self) -> int:
        return len(self._entries)

    def get(
        self,
        views: Sequence[TaughtTopView],
        *,
        camera: PinholeCamera,
        z_floor_m: float,
        z_top_m: float,
    ) -> FeatureHeights:
        """The heights of ``views`` (:func:`triangulate_heights`), from the cache when the
        same views and calibration were triangulated before."""
        views = sorted(views, key=lambda v: v.view_id)[:MAX_VIEWS]
        key = _fingerprint(views, camera, (z_floor_m, z_top_m))
        with self._lock:
            hit = self._entries.get(key)
            if hit is not None:
                self._entries.move_to_end(key)
                return hit
        with self._computing:
            with self._lock:
                hit = self._entries.get(key)
            if hit is None:
                hit = triangulate_heights(views, camera=camera, z_floor_m=z_floor_m,
                                          z_top_m=z_top_m)  # fmt: skip
            with self._lock:
                self._entries[key] = hit
                self._entries.move_to_end(key)
                while len(self._entries) > self._max:
                    self._entries.popitem(last=False)
        return hit
