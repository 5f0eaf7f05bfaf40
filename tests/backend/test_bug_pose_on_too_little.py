"""A pose resting on too little is looked at again, not picked.

A fresh pipe-flange run (seed 8) gave 5 poses of 139 off by 1.2 to 6.8 mm or 1.2 to
118.6 deg.  Each came from one trained view with 5-7 correspondences: the joint fit needs
``MIN_PARALLAX_POINTS``, so each was the plane answer (``ObjectPose.method == "plane"``),
and over the 483 fits recorded then no other answer was.  The inspection now takes a
second top view, turned about the camera's axis (:func:`_second_top_view`): its joint fit
is taken; two plane answers only when they agree; otherwise the object has no pose (it goes
to the reject bin) and the reason says why.

These tests drive the decision with a stand-in cell and pose fit: the second view's
joints, the region its features are taken in, and each rule of the choice.
"""

from __future__ import annotations

import asyncio
import math
from types import SimpleNamespace
from typing import Any

import cv2
import numpy as np
import pytest

from backend.calibration import NOMINAL_T_EE_CAM
from backend.calibration.auto import nominal_camera
from backend.inspection import look, secondtop
from backend.inspection import pose as pose_stage
from backend.inspection.context import Context, cam_pose
from backend.inspection.options import InspectOptions
from backend.inspection.stopwatch import Stopwatch
from backend.planning import AIM_HEIGHT_M, plan_shots
from robot.drivers.conveyor import BeltStatus, FixedStation
from robot.errors import Unreachable
from robot.sim.world import ConveyorSpec
from vision.pose import ObjectPose, PoseFailed, rests_on_too_little

SPEC = ConveyorSpec()
CAMERA = nominal_camera(640, 480)
T_EE_CAM = np.asarray(NOMINAL_T_EE_CAM, dtype=np.float64)
TOP_SHOT = plan_shots(
    SPEC.station_point, (1,), T_ee_cam=T_EE_CAM, object_height_m=AIM_HEIGHT_M,
    top_rolls_rad=(0.0,),
)[0]  # fmt: skip
T_CAM_TOP = cam_pose(TOP_SHOT.q, T_EE_CAM)


def _top_mask() -> np.ndarray:
    """The object's region in the top view: a 60 mm disc at the station, 50 mm high."""
    centre = SPEC.station_point + np.array([0.0, 0.0, 0.05])
    p = np.linalg.inv(T_CAM_TOP) @ np.r_[centre, 1.0]
    u = CAMERA.K @ (p[:3] / p[2])
    r_px = CAMERA.K[0, 0] * 0.06 / p[2]
    mask = np.zeros((480, 640), np.uint8)
    cv2.circle(mask, (round(float(u[0])), round(float(u[1]))), round(float(r_px)), 1, -1)
    return mask.astype(bool)


def _pose(x_mm: float, yaw_deg: float, method: str, n: int = 6, views: int | None = None,
          y_mm: float = 0.0) -> ObjectPose:  # fmt: skip
    T = np.eye(4)
    a = math.radians(yaw_deg)
    T[:2, :2] = [[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]]
    T[:3, 3] = SPEC.station_point + np.array([x_mm * 1e-3, y_mm * 1e-3, 0.0])
    views = (1 if method == "plane" else 3) if views is None else views
    return ObjectPose(T, a, 0.0, n, method, views=views)


class _Cell:
    def __init__(self, travel_m: float | None = None) -> None:
        self.looked: list[np.ndarray] = []
        self.meta = {} if travel_m is None else {"belt_travel_m": travel_m}

    async def look(self, q: Any, speed: Any = None) -> Any:
        self.looked.append(np.asarray(q, dtype=np.float64))
        rgb = np.full((480, 640, 3), 90, np.uint8)
        state = SimpleNamespace(q=np.asarray(q))
        return SimpleNamespace(rgb=rgb, robot_state=state, meta=dict(self.meta))


class _Live:
    def __init__(self) -> None:
        self.masks: list[np.ndarray] = []

    def extract(self, image: np.ndarray, mask: np.ndarray) -> str:
        self.masks.append(mask)
        return "features of the second top view"


def _run(monkeypatch: pytest.MonkeyPatch, first: ObjectPose | None, second: Any,
         first_err: str = "", belt: tuple[float, float] | None = None,
         ) -> tuple[Any, _Cell, _Live, list[tuple[Any, ...]]]:  # fmt: skip
    """The second top view after ``first``, the fit there answering ``second``; ``belt``:
    (travel now, travel at the second exposure) of a belt running at 0.05 m/s from 0."""
    cell, live = _Cell(None if belt is None else belt[1]), _Live()
    conveyor: Any = FixedStation()
    if belt is not None:
        status = BeltStatus(True, False, "continuous", 0.05, False, belt[0], None)
        conveyor = SimpleNamespace(controllable=True, status=lambda: status,
                                   travel_at=lambda t_s=None: belt[0])  # fmt: skip
    rt = SimpleNamespace(cell=cell, live_index=live, conveyor=conveyor)
    ctx = Context(rt, CAMERA, T_EE_CAM, "test", SPEC.station_point, SPEC.surface_z_m,
                       belt_end_y_m=SPEC.station_point[1] + 1.0)  # fmt: skip
    calls: list[tuple[Any, ...]] = []

    async def fake_pose(ctx: Any, cand: Any, model: str, T_cam: Any, height: float,
                        query: Any = None, query_mask: Any = None) -> ObjectPose:  # fmt: skip
        calls.append((cand, model, T_cam, query, query_mask))
        if isinstance(second, Exception):
            raise second
        return second

    monkeypatch.setattr(pose_stage, "estimate", fake_pose)
    opts = InspectOptions()
    got = asyncio.run(secondtop.second_top_view(
        ctx, opts, "pipe-flange", SPEC.station_point.copy(), watch=Stopwatch(), first=first,
        first_err=first_err,
        T_plan=T_EE_CAM, top_mask=_top_mask(), T_cam_top=T_CAM_TOP, height=0.05, travel0=0.0,
        gain=None, mode="index" if belt is None else "continuous",
        speed_m_s=0.0 if belt is None else 0.05,
    ))  # fmt: skip
    return got, cell, live, calls


def test_the_second_view_is_turned_and_its_region_is_the_objects(monkeypatch) -> None:
    got, cell, live, calls = _run(
        monkeypatch, _pose(4.0, 2.0, "plane"), _pose(0.2, 0.1, "parallax", 30)
    )
    # one look, turned about the camera's axis by the roll (the flange joint q5)
    assert len(cell.looked) == 1
    dq = cell.looked[0] - TOP_SHOT.q
    assert abs(abs(math.remainder(dq[4], 2 * math.pi)) - secondtop.SECOND_TOP_ROLL_RAD) < 0.05
    assert np.allclose(dq[:4], 0.0, atol=0.05)
    # the pose fit is led by the best verified view (no candidate), on the new view's
    # features and region; that region is the object's, not the frame
    cand, model, T_cam, query, mask = calls[0]
    assert cand is None and model == "pipe-flange"
    assert query == "features of the second top view"
    assert np.allclose(T_cam, cam_pose(cell.looked[0], T_EE_CAM))
    top_area = _top_mask().sum()
    assert mask is live.masks[0] and 0.8 * top_area < mask.sum() < 2.0 * top_area
    # the joint fit of the second view is taken, of its exposure, with its image stored
    assert got.pose is not None and got.pose.method == "parallax"
    assert got.used and got.error == "" and got.summary["chosen"] == "second"
    _frame, T_cam2, record = got.shot
    assert np.allclose(T_cam2, T_cam) and record.viewpoint == 1 and record.jpeg[:2] == b"\xff\xd8"
    assert got.summary["first"]["method"] == "plane"
    assert got.summary["second"]["method"] == "parallax"


def test_two_plane_answers_that_agree_are_taken(monkeypatch) -> None:
    first = _pose(0.5, 0.2, "plane")
    got, *_ = _run(monkeypatch, first, _pose(1.4, 0.6, "plane"))
    assert got.pose is first and not got.used and got.summary["chosen"] == "first"


@pytest.mark.parametrize(
    ("second", "why"),
    [
        (_pose(4.5, 0.2, "plane"), "4.0 mm and 0.0 deg from the first"),  # moved
        (_pose(0.5, 1.5, "plane"), "0.0 mm and 1.3 deg from the first"),  # turned
        (_pose(3.0, 0.2, "parallax", 12, views=1), "one trained view's 12 correspondences"),
        (PoseFailed("no trained top view of pipe-flange verified on this view"), "verified"),
    ],
)
def test_plane_answers_that_disagree_leave_no_pose(monkeypatch, second, why) -> None:
    got, cell, _live, _calls = _run(monkeypatch, _pose(0.5, 0.2, "plane", n=5), second)
    assert got.pose is None and "chosen" not in got.summary
    assert got.error.startswith("the top view's pose rested on too little (the plane answer")
    assert why in got.error
    assert got.shot is not None and len(cell.looked) == 1  # the look is stored all the same


def test_no_first_pose_and_a_second_joint_fit(monkeypatch) -> None:
    got, *_ = _run(monkeypatch, None, _pose(0.1, 0.1, "parallax", 20),
                   first_err="the top view did not verify the recognised model")  # fmt: skip
    assert got.pose is not None and got.used
    assert got.summary["first"] == {"error": "the top view did not verify the recognised model"}
    got, *_ = _run(monkeypatch, None, _pose(0.1, 0.1, "plane"),
                   first_err="the top view did not verify the recognised model")  # fmt: skip
    assert got.pose is None
    assert got.error.startswith("the top view did not verify the recognised model; ")


def test_an_unreachable_second_view_leaves_no_pose(monkeypatch) -> None:
    def unreachable(*a: Any, **k: Any) -> Any:
        raise Unreachable("outside the workspace")

    monkeypatch.setattr(look, "plan_viewpoints", unreachable)
    got, cell, _live, calls = _run(monkeypatch, _pose(0.5, 0.2, "plane"), _pose(0, 0, "parallax"))
    assert got.pose is None and got.shot is None and not cell.looked and not calls
    assert "cannot be reached: outside the workspace" in got.error


def test_what_rests_on_too_little() -> None:
    assert rests_on_too_little(None)
    assert rests_on_too_little(_pose(0, 0, "plane"))
    # one trained view's own joint fit: 3.0 mm off on 12 correspondences in a fresh run
    assert rests_on_too_little(_pose(0, 0, "parallax", 12, views=1))
    assert not rests_on_too_little(_pose(0, 0, "parallax", 12, views=2))


def test_a_first_view_of_one_trained_view_alone_is_checked_too(monkeypatch) -> None:
    first = _pose(3.0, 0.3, "parallax", 12, views=1)
    got, *_ = _run(monkeypatch, first, _pose(0.1, 0.1, "parallax", 30, views=4))
    assert got.used and got.pose.views == 4
    got, *_ = _run(monkeypatch, first, _pose(2.6, 0.1, "parallax", 10, views=1))
    assert got.pose is first  # two one-view answers that agree
    got, *_ = _run(monkeypatch, first, _pose(0.1, 0.1, "parallax", 10, views=1))
    assert got.pose is None and "rested on too little (one trained view's 12" in got.error


def test_at_constant_speed_the_first_answer_is_carried_before_they_are_compared(
    monkeypatch,
) -> None:
    """The belt carried the object 80 mm between the exposures: two answers that agree
    once the first is carried are taken (the first, of the top view's exposure); without
    the carrying they would be 80 mm apart."""
    first = _pose(0.3, 0.2, "plane")
    got, _cell, _live, calls = _run(
        monkeypatch, first, _pose(0.3, 0.4, "plane", y_mm=80.5), belt=(0.02, 0.08)
    )
    assert got.pose is first and not got.used and got.summary["chosen"] == "first"
    # the view was planned over where the belt will have carried it, not at the station
    T_cam = calls[0][2]
    assert T_cam[1, 3] > T_CAM_TOP[1, 3] + 0.05
    got, *_ = _run(monkeypatch, first, _pose(0.3, 0.4, "plane", y_mm=86.0), belt=(0.02, 0.08))
    assert got.pose is None and "6.0 mm and 0.2 deg from the first" in got.error
