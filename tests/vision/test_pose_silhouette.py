"""Answers judged by the outline (vision.pose.silhouette) on a square seen straight down,
where the overlap of a moved region is counted by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vision.camera import PinholeCamera
from vision.pose import ObjectPose, SilhouetteView, fixed_mask, silhouette_overlap
from vision.pose.silhouette import choose_by_silhouette

#: 2 mm per pixel on the plane z = 0 seen from 1 m.
CAM = PinholeCamera(np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]]))
T_CAM = np.diag([1.0, -1.0, -1.0, 1.0])
T_CAM[2, 3] = 1.0
#: A 100 x 100 px square (20 x 20 cm on the plane).
SQUARE = np.zeros((480, 640), bool)
SQUARE[150:250, 200:300] = True


def _shift(dx_m: float) -> np.ndarray:
    T = np.eye(4)
    T[0, 3] = dx_m
    return T


def _overlap(T_delta: np.ndarray, query: np.ndarray = SQUARE) -> float:
    return silhouette_overlap(SQUARE, query, camera=CAM, T_base_cam_view=T_CAM,
                              T_base_cam_now=T_CAM, T_delta=T_delta, z_m=0.0)  # fmt: skip


def test_the_region_moved_by_the_true_motion_overlaps_whole():
    assert _overlap(np.eye(4)) == pytest.approx(1.0)
    moved = np.zeros_like(SQUARE)
    moved[150:250, 250:350] = True  # the square moved 50 px = 0.1 m along base x
    assert _overlap(_shift(0.1), moved) == pytest.approx(1.0)


def test_a_wrong_answer_overlaps_by_the_counted_share():
    # Moved 50 px too far; the search shifts it back by at most round(0.04 * 99) = 4 px:
    # 54 x 100 px in common, 2 x 10,000 - 5,400 in the union.
    assert _overlap(_shift(0.1)) == pytest.approx(5400 / 14600, abs=1e-9)
    # Within the search's 4 px (8 mm) the overlap stays whole.
    assert _overlap(_shift(0.008)) == pytest.approx(1.0)


def test_empty_regions_and_a_plane_behind_the_camera():
    empty = np.zeros_like(SQUARE)
    assert _overlap(np.eye(4), empty) == 0.0
    got = silhouette_overlap(SQUARE, SQUARE, camera=CAM, T_base_cam_view=T_CAM,
                             T_base_cam_now=T_CAM, T_delta=np.eye(4), z_m=2.0)  # fmt: skip
    assert math.isnan(got)


def _answer(dx_m: float) -> ObjectPose:
    return ObjectPose(_shift(dx_m), 0.0, 0.001, 40)


VIEW = SilhouetteView(T_CAM, np.eye(4), fixed_mask(SQUARE))


@pytest.mark.parametrize(("n_second", "pick"), [(60, 1), (19, 0)])
def test_the_outline_overrules_more_correspondences_only_for_a_fair_share(n_second, pick):
    # The first group (100 correspondences) puts the square 0.1 m off, the second exactly;
    # the second is considered only with at least 20 % of the first's correspondences.
    record, got = choose_by_silhouette(
        [(_answer(0.1), 3, 100), (_answer(0.0), 2, n_second)], camera=CAM,
        T_base_cam_now=T_CAM, z_m=0.0, query_mask=SQUARE, silhouettes=[VIEW],
    )  # fmt: skip
    assert got == pick
    assert [r["chosen"] for r in record] == [pick == 0, pick == 1]
    assert record[0]["silhouette_iou"] == pytest.approx(round(5400 / 14600, 4))
    assert record[1]["silhouette_iou"] == pytest.approx(1.0)
    assert record[0]["views"] == 3 and record[1]["correspondences"] == n_second
    assert record[0]["position_m"] == pytest.approx([0.1, 0.0, 0.0])


def test_without_a_current_region_the_most_correspondences_decide():
    record, got = choose_by_silhouette(
        [(_answer(0.1), 3, 100), (_answer(0.0), 2, 60)], camera=CAM, T_base_cam_now=T_CAM,
        z_m=0.0, query_mask=None, silhouettes=[VIEW],
    )  # fmt: skip
    assert got == 0 and [r["silhouette_iou"] for r in record] == [None, None]
